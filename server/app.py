"""Assemble the device server: the landscape.v1 services on grpc.aio, health and reflection.

The server's event loop runs on a thread of its own (`serve` returns a handle at once), so
`python -m landscape.server` and the tests drive it the same way. Streams cost no thread;
command bodies run on the guard's thread pools (servicers/guard.py).
"""
from __future__ import annotations

import asyncio
import dataclasses
import logging
import sys
import threading
from dataclasses import dataclass

import grpc
from grpc_health.v1 import health, health_pb2, health_pb2_grpc
from grpc_reflection.v1alpha import reflection, reflection_pb2_grpc

from landscape.bridges.metrics.endpoint import (MetricsEndpoint, MetricsExposed, MetricsTLS,
                                                new_registry, serve_metrics)
from landscape.server.events import alarms
from landscape.server.metrics import DeviceMetrics
from landscape.server.api import services
from landscape.server.security import tls
from landscape.server.security.audit import AuditLog
from landscape.server.security.auth import TokenFileError, TokenStore
from landscape.server.planning.collision import CollisionScene
from landscape.server.config import SecurityConfig, ServerConfig
from landscape.server.link.controller_link import ControllerLink
from landscape.server.device.device import Device
from landscape.server.events.bus import EventBus
from landscape.server.api.stream_caps import StreamLimits
from landscape.server.listen import listen_address, listen_problem
from landscape.server.planning.paths import PathStore
from landscape.server.security.rate_limit import RateLimiter
from landscape.server.api.reflection_pool import MethodResolvingPool
from landscape.server.security.interceptor import SecurityInterceptor
from landscape.server.api.servicers.audit import AuditServicer
from landscape.server.api.servicers.device import DeviceServicer
from landscape.server.api.servicers.digital_io import DigitalIOServicer
from landscape.server.api.servicers.events import EventServicer
from landscape.server.api.servicers.recording import RecordingServicer
from landscape.server.api.guard import Dispatch
from landscape.server.api.servicers.session import SessionServicer
from landscape.server.api.servicers.state import StateServicer
from landscape.server.api.state_stream import StateHub
from landscape.server.workcell.assembly import Workcell, build_workcell
from landscape.robot.cell import load_cell
from landscape.robot.cell_model import Pose

log = logging.getLogger(__name__)


class StartupError(RuntimeError):
    """The server cannot start; the message names the cause and the fix, in one line."""


class _LoopThread:
    """An asyncio event loop on a daemon thread; `run(coro)` runs a coroutine on it and
    returns its result to the calling thread."""

    def __init__(self):
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._main, name="grpc-loop", daemon=True)
        self._thread.start()

    def _main(self) -> None:
        asyncio.set_event_loop(self.loop)
        self.loop.run_forever()

    def run(self, coro, timeout: float | None = 60.0):
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout)

    def close(self) -> None:
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(5.0)
        if not self._thread.is_alive():
            self.loop.close()


@dataclass
class RunningServer:
    server: grpc.aio.Server
    health: health.aio.HealthServicer
    port: int
    address: str
    bus: EventBus
    device: Device
    workcell: Workcell
    link: ControllerLink
    hub: StateHub
    dispatch: Dispatch
    limits: StreamLimits
    runner: _LoopThread
    security: SecurityInterceptor
    metrics: MetricsEndpoint | None = None
    device_metrics: DeviceMetrics | None = None

    @property
    def target(self) -> str:
        return f"{self.address}:{self.port}"

    def set_serving(self, serving: bool) -> None:
        """gRPC health of the device's services (thread-safe)."""
        status = (health_pb2.HealthCheckResponse.SERVING if serving
                  else health_pb2.HealthCheckResponse.NOT_SERVING)

        async def update():
            for name in ("", *(spec.full_name for spec in services.ALL)):
                await self.health.set(name, status)
        asyncio.run_coroutine_threadsafe(update(), self.runner.loop)

    def stop(self, grace: float | None = 1.0) -> None:
        """Leave the arm safe (the lock holder's session ends: its disconnect handler stops,
        deactivates and releases), end the streams, stop serving and the controller."""
        self.runner.run(self.health.enter_graceful_shutdown())
        self.device.close()
        self.workcell.close()
        self.bus.close()
        self.runner.run(self.hub.aclose())
        self.runner.run(self.server.stop(grace), timeout=None)
        self.dispatch.shutdown()
        self.link.stop()
        self.runner.close()
        self.security.close()
        if self.metrics is not None:
            self.metrics.close()
            self.device_metrics.close()

    def wait(self) -> None:
        self.runner.run(self.server.wait_for_termination(), timeout=None)


def serve(config: ServerConfig = ServerConfig()) -> RunningServer:
    """Start a device server with its controller; returns once it listens (config.port 0 picks
    a free port) and, if config.start_device, once the controller is initialised. Raises
    StartupError (one line: cause and fix) if the address cannot be had, or the security
    settings cannot be used or do not allow that address (tls.exposure_problem)."""
    problem = tls.exposure_problem(config.address, config.security)
    if problem:
        raise StartupError(problem)
    # A thread that computes (planning a long path) keeps the interpreter for up to the switch
    # interval before the event loop or a stop gets it back, and a stop changes hands a few
    # times on its way to the pipe: 0.2 ms instead of Python's 5 on the real-time clock
    # (bench_stop: p99 under long planning 8.4 ms, 13.9 at 1 ms). The lock-step clock's
    # thread computes too, and pays for every hand-over (bench_lockstep: 12 % slower at 0.2).
    sys.setswitchinterval(0.001 if config.clock == "lockstep" else 0.0002)
    bus = EventBus()
    device: Device | None = None
    metrics = None if config.metrics_port is None else DeviceMetrics(
        new_registry(), cycle_samples=lambda seen: link.cycle_samples(seen),
        cycle_pid=lambda: link.cycle_pid,
        state=lambda: _device_state(device),
        sessions=lambda: device.sessions.count(), streams=lambda kind: limits.open(kind),
        subscribers=lambda: bus.subscriber_count, queues=lambda: _queues(dispatch, security))
    security = _security_layer(config.security, report=lambda severity, message: bus.alarm(
        severity, alarms.AUDIT, message), timing=metrics and metrics.rpc_timing)
    runner = _LoopThread()
    try:
        server, port = runner.run(_bind(config, security))
    except BaseException:
        runner.close()
        security.close()
        raise
    cell = load_cell(config.cell)
    if config.placement is not None:
        cell = dataclasses.replace(cell, shared_cell=config.shared_cell, placement=Pose(
            config.placement[:3], config.placement[3:]))
    link = ControllerLink(config.clock, config.cell,
                          on_message=lambda msg: device and device.on_cycle_message(msg),
                          on_lost=lambda why: device and device.controller_lost(why),
                          pace=config.lockstep_pace, backend=config.backend)
    outputs = {signal.name for signal in cell.io.signals if signal.direction == "output"}
    paths = PathStore(config.paths_file, report=lambda severity, message: bus.alarm(
        severity, alarms.STORAGE, message))
    device = Device(link, bus, cell.arm, paths=paths, outputs=outputs,
                    reset_settings=config.reset_settings, settings_delay=config.settings_delay,
                    collisions=CollisionScene(cell, config.collision_margin))
    workcell = build_workcell(device, cell)
    hub = StateHub(device, workcell, max_lag=250 if config.clock == "realtime" else 8)
    dispatch, limits = Dispatch(), StreamLimits(config.stream_caps)
    try:
        if config.start_device:
            device.start()
        health_servicer = runner.run(_start(server, device, workcell, bus, hub, dispatch,
                                            limits, cell.recorder.path, config.security))
    except BaseException:
        device.close()
        workcell.close()
        link.stop()
        runner.run(server.stop(None))
        runner.close()
        security.close()
        raise
    running = RunningServer(server, health_servicer, port, config.address, bus, device, workcell,
                            link, hub, dispatch, limits, runner, security)
    device.on_health = running.set_serving
    if metrics is not None:
        try:
            running.metrics = _serve_metrics(config, metrics, device, bus)
        except BaseException:
            running.stop(grace=None)
            raise
        running.device_metrics = metrics
    return running


def _serve_metrics(config: ServerConfig, metrics: DeviceMetrics, device: Device,
                   bus: EventBus) -> MetricsEndpoint:
    """/metrics on, with the planner timed and the bus watched; StartupError if it cannot."""
    motions = device.motions
    motions.planner = metrics.time_planning(motions.planner, ("move", "arc"))
    device.path_runs.planning = metrics.time_planning(device.path_runs.planning, ("run",))
    metrics.watch(bus)
    security = config.security
    tls = (MetricsTLS(security.tls_cert, security.tls_key, security.tls_ca if security.mtls
                      else None) if security.tls_enabled else None)
    try:
        return serve_metrics(metrics.registry, config.metrics_address, config.metrics_port,
                             tls, security.insecure)
    except MetricsExposed as error:
        raise StartupError(str(error)) from None
    except OSError as error:
        raise StartupError(f"cannot serve /metrics on {config.metrics_address}:"
                           f"{config.metrics_port}: {error.strerror}; choose another with "
                           f"--metrics-port") from None


def _device_state(device: Device) -> tuple[str, bool]:
    status = device.status()
    return status.state.value, status.estop


def _queues(dispatch: Dispatch, security: SecurityInterceptor) -> dict[str, int]:
    depths = dispatch.in_flight()
    if security.audit is not None:
        depths["audit"] = security.audit.backlog
    return depths


def _security_layer(security: SecurityConfig, report, timing=None) -> SecurityInterceptor:
    """Tokens, audit log and rate limit as configured; StartupError naming what is wrong.
    `report` (severity, message): the audit log's troubles (audit.py); `timing`: the RPC
    latency metric's hook, if /metrics is on."""
    try:
        tokens = TokenStore.load(security.tokens) if security.tokens else None
    except TokenFileError as error:
        raise StartupError(f"tokens: {error}") from None
    try:
        rate = (RateLimiter(security.rate_limit, security.rate_burst, security.rate_limits)
                if security.rate_limit else None)
    except ValueError as error:
        raise StartupError(f"rate limits: {error}") from None
    try:
        audit = (AuditLog(security.audit_log, security.audit_max_bytes, security.audit_backups,
                          report) if security.audit_log else None)
    except OSError as error:
        raise StartupError(f"cannot write the audit log {security.audit_log}: "
                           f"{error.strerror}; choose another with --audit-log") from None
    return SecurityInterceptor(tokens, audit, rate, timing)


async def _bind(config: ServerConfig,
                security: SecurityInterceptor) -> tuple[grpc.aio.Server, int]:
    server = grpc.aio.server(interceptors=[] if security.idle else [security],
                             options=[("grpc.max_receive_message_length", config.max_message_bytes),
                                      ("grpc.so_reuseport", 0)])
    where = listen_address(config.address, config.port)
    try:
        credentials = (tls.server_credentials(config.security)
                       if config.security.tls_enabled else None)
    except tls.TlsError as error:
        raise StartupError(f"TLS: {error}; make development certificates with "
                           f"`landscape-cell certs`") from None
    try:
        port = (server.add_secure_port(where, credentials) if credentials
                else server.add_insecure_port(where))
    except RuntimeError:
        port = 0
    if port == 0:   # gRPC does not say why: a trial bind does (or did, just before)
        raise StartupError(listen_problem(config.address, config.port) or
                           f"cannot listen on {where}: the port is in use or the address is "
                           f"not this machine's; choose another with --port / --address")
    return server, port


async def _start(server, device, workcell, bus, hub, dispatch, limits, recording: str,
                 security: SecurityConfig):
    hub.attach(asyncio.get_running_loop())
    servicers = {
        services.DEVICE: DeviceServicer(device, workcell, hub, dispatch, limits),
        services.DIGITAL_IO: DigitalIOServicer(device, workcell, dispatch, limits),
        services.EVENTS: EventServicer(device, bus, dispatch, limits),
        services.SESSIONS: SessionServicer(device, dispatch, limits),
        services.STATE: StateServicer(device, hub, dispatch, limits),
        services.RECORDINGS: RecordingServicer(device, recording, dispatch, limits),
        services.AUDIT: AuditServicer(device, security.audit_log, security.audit_backups,
                                      dispatch, limits),
    }
    for spec, servicer in servicers.items():
        spec.add_to_server(servicer, server)
    health_servicer = health.aio.HealthServicer()
    health_pb2_grpc.add_HealthServicer_to_server(health_servicer, services.GenericOnly(server))
    status = health_pb2.HealthCheckResponse.SERVING
    for name in ("", *(spec.full_name for spec in services.ALL)):
        await health_servicer.set(name, status)
    reflection_pb2_grpc.add_ServerReflectionServicer_to_server(reflection.aio.ReflectionServicer(
        (*(spec.full_name for spec in services.ALL), health.SERVICE_NAME, reflection.SERVICE_NAME),
        pool=MethodResolvingPool()), services.GenericOnly(server))
    await server.start()
    return health_servicer
