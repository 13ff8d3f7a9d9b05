"""Assemble the device server: the landscape.v1 services, gRPC health checking and reflection."""
from __future__ import annotations

import logging
from concurrent import futures
from dataclasses import dataclass

import grpc
from grpc_health.v1 import health, health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection

from landscape.server import services
from landscape.server.config import ServerConfig
from landscape.server.controller_link import open_link
from landscape.server.device import Device
from landscape.server.errors import ErrorMappingInterceptor
from landscape.server.events import EventBus
from landscape.server.paths import PathStore
from landscape.server.reflection_pool import MethodResolvingPool
from landscape.server.servicers.device import DeviceServicer
from landscape.server.stream_limit import StreamLimitInterceptor
from landscape.server.servicers.digital_io import DigitalIOServicer
from landscape.server.servicers.events import EventServicer
from landscape.server.servicers.session import SessionServicer
from landscape.server.servicers.state import StateServicer
from landscape.sim.cell import load_cell

log = logging.getLogger(__name__)


@dataclass
class RunningServer:
    server: grpc.Server
    health: health.HealthServicer
    port: int
    address: str
    bus: EventBus
    device: Device
    link: object

    @property
    def target(self) -> str:
        return f"{self.address}:{self.port}"

    def stop(self, grace: float | None = 1.0) -> None:
        self.health.enter_graceful_shutdown()
        self.device.close()  # sessions end: the disconnect handler leaves the arm safe
        self.bus.close()     # ends the event streams cleanly within the grace period
        self.server.stop(grace).wait()
        self.link.stop()

    def wait(self) -> None:
        self.server.wait_for_termination()


def serve(config: ServerConfig = ServerConfig()) -> RunningServer:
    """Start a device server with its controller; returns once it listens (config.port 0 picks
    a free port) and, if config.start_device, once the controller is initialised."""
    bus = EventBus()
    cell = load_cell(config.cell)
    device: Device | None = None
    link = open_link(config.clock, config.cell, lambda msg: device and device.on_cycle_message(msg),
                     config.lockstep_pace)
    outputs = {signal.name for signal in cell.io.signals if signal.direction == "output"}
    device = Device(link, bus, cell.arm, paths=PathStore(config.paths_file), outputs=outputs)
    if config.start_device:
        device.start()

    server = grpc.server(
        futures.ThreadPoolExecutor(max_workers=config.max_workers, thread_name_prefix="rpc"),
        interceptors=[StreamLimitInterceptor(config.max_streams), ErrorMappingInterceptor()],
        options=[("grpc.max_receive_message_length", config.max_message_bytes),
                 ("grpc.so_reuseport", 0)],
    )
    servicers = {services.DEVICE: DeviceServicer(device), services.DIGITAL_IO: DigitalIOServicer(device),
                 services.EVENTS: EventServicer(bus), services.SESSIONS: SessionServicer(device),
                 services.STATE: StateServicer(device)}
    for spec, servicer in servicers.items():
        spec.add_to_server(servicer, server)

    health_servicer = health.HealthServicer()
    health_pb2_grpc.add_HealthServicer_to_server(health_servicer, server)
    for name in ("", *(spec.full_name for spec in services.ALL)):
        health_servicer.set(name, health_pb2.HealthCheckResponse.SERVING)

    reflection.enable_server_reflection(
        (*(spec.full_name for spec in services.ALL), health.SERVICE_NAME, reflection.SERVICE_NAME),
        server, pool=MethodResolvingPool())

    port = server.add_insecure_port(f"{config.address}:{config.port}")
    if port == 0:
        raise OSError(f"cannot listen on {config.address}:{config.port}")
    server.start()
    log.info("device server listening on %s:%d", config.address, port)
    return RunningServer(server, health_servicer, port, config.address, bus, device, link)
