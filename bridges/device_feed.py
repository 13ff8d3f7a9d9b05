"""One device server as a bridge sees it: a watcher of its state and event streams, like the
web supervisor, never a lock holder.

`DeviceFeed.run()` connects, reads the arm's description and I/O map, then hands every state
sample (SI units, the tool pose in the base frame, at the rate asked: the device thins the
stream, so a bridge costs the cycle nothing) and every event to its callbacks, and polls the
digital I/O and the device's status (state, lock holder). When the device goes away it says so and connects again, every few seconds,
until `close()`.
"""
from __future__ import annotations

import asyncio
import inspect
import logging
from collections.abc import Callable
from dataclasses import dataclass

import grpc

from landscape.client.credentials import ClientTLS, open_aio_channel
from landscape.client.identity import Identity
from landscape.v1 import (control_pb2, device_service_pb2_grpc, digital_io_service_pb2,
                          digital_io_service_pb2_grpc, event_service_pb2, event_service_pb2_grpc,
                          state_service_pb2, state_service_pb2_grpc, types_pb2)

log = logging.getLogger(__name__)

RETRY = 2.0          # s between attempts to reach a device that went away
IO_PERIOD = 0.2      # s between reads of the digital I/O
SI = types_pb2.Units(linear=types_pb2.LINEAR_UNIT_METERS, angular=types_pb2.ANGULAR_UNIT_RADIANS)


@dataclass(frozen=True)
class Description:
    """What a bridge learns once per connection: the arm's type, URDF and joint names, and
    the I/O map (units with their named bits)."""

    robot_type: str
    urdf: str
    joint_names: tuple[str, ...]
    io_units: tuple


@dataclass
class Callbacks:
    """What a bridge does with what the device says: plain functions or coroutine functions
    (awaited before the next message: a slow one makes the device thin the stream further)."""

    connected: Callable[[Description], None]
    sample: Callable[[state_service_pb2.StateSample], None]
    event: Callable[[event_service_pb2.Event], None]
    io: Callable[[list[tuple[object, int]]], None]     # [(DigitalIOUnit, bits_on)]
    lost: Callable[[str], None]
    status: Callable[[control_pb2.GetDeviceStateResponse], None] | None = None


async def _call(callback, *args) -> None:
    result = callback(*args)
    if inspect.isawaitable(result):
        await result


class DeviceFeed:
    def __init__(self, name: str, target: str, callbacks: Callbacks, *, rate_hz: float = 30.0,
                 sensors: tuple[str, ...] = (), tls: ClientTLS | None = None,
                 token: str | None = None, client: str = "bridge"):
        self.name, self.target, self.callbacks = name, target, callbacks
        self.rate_hz, self.sensors = rate_hz, tuple(sensors)
        self.tls, self.token = tls, token
        self.metadata = Identity(client).metadata()
        self._closed = asyncio.Event()

    async def run(self) -> None:
        while not self._closed.is_set():
            channel = open_aio_channel(self.target, self.tls, self.token)
            try:
                await self._serve(channel)
            except grpc.aio.AioRpcError as error:
                await _call(self.callbacks.lost, f"{self.name} ({self.target}): "
                                                 f"{error.code().name}: {error.details()}")
            finally:
                await channel.close()
            try:
                await asyncio.wait_for(self._closed.wait(), RETRY)
            except TimeoutError:
                pass

    def close(self) -> None:
        self._closed.set()

    async def _serve(self, channel) -> None:
        device = device_service_pb2_grpc.DeviceServiceStub(channel)
        io = digital_io_service_pb2_grpc.DigitalIOServiceStub(channel)
        about = await device.GetRobotDescription(control_pb2.GetRobotDescriptionRequest(),
                                                 metadata=self.metadata, timeout=10)
        units = (await io.ListDigitalIO(digital_io_service_pb2.ListDigitalIORequest(),
                                        metadata=self.metadata, timeout=10)).units
        await _call(self.callbacks.connected, Description(
            about.robot_type, about.urdf, tuple(about.joint_names), tuple(units)))
        tasks = [asyncio.create_task(self._states(channel)),
                 asyncio.create_task(self._events(channel)),
                 asyncio.create_task(self._poll(device, io, units)),
                 asyncio.create_task(self._closed.wait())]
        try:
            done, _ = await asyncio.wait(tasks, return_when=asyncio.FIRST_COMPLETED)
            for task in done:
                task.result()   # a stream's error ends the connection (run says why)
        finally:
            for task in tasks:
                task.cancel()
            await asyncio.gather(*tasks, return_exceptions=True)

    async def _states(self, channel) -> None:
        stub = state_service_pb2_grpc.StateServiceStub(channel)
        sensors = self.sensors
        while True:
            request = state_service_pb2.StreamStateRequest(
                rate_hz=self.rate_hz, frame=types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME,
                units=SI, sensors=sensors)
            try:
                async for reply in stub.StreamState(request, metadata=self.metadata):
                    if reply.HasField("sample"):
                        await _call(self.callbacks.sample, reply.sample)
                return
            except grpc.aio.AioRpcError as error:
                if error.code() is not grpc.StatusCode.INVALID_ARGUMENT or not sensors:
                    raise
                log.warning("%s: the sensors %s cannot be streamed (%s); going on without",
                            self.name, ", ".join(sensors), error.details())
                sensors = ()

    async def _events(self, channel) -> None:
        stub = event_service_pb2_grpc.EventServiceStub(channel)
        async for reply in stub.Subscribe(event_service_pb2.SubscribeRequest(),
                                          metadata=self.metadata):
            if reply.HasField("event"):
                await _call(self.callbacks.event, reply.event)

    async def _poll(self, device, io, units) -> None:
        """The digital I/O and the status, every IO_PERIOD (reads: no stream carries them)."""
        while True:
            values = []
            for unit in units:
                reply = await io.GetDigitalIO(digital_io_service_pb2.GetDigitalIORequest(
                    type=unit.type, unit_id=unit.unit_id), metadata=self.metadata, timeout=10)
                values.append((unit, reply.bits_on))
            await _call(self.callbacks.io, values)
            if self.callbacks.status is not None:
                await _call(self.callbacks.status, await device.GetDeviceState(
                    control_pb2.GetDeviceStateRequest(), metadata=self.metadata, timeout=10))
            await asyncio.sleep(IO_PERIOD)


def device_targets(parser, items: list[str]) -> dict[str, str]:
    """{name: host:port} from a bridge's --device NAME=HOST:PORT arguments (parser.error on a
    malformed one, or none)."""
    devices = {}
    for item in items:
        name, _, target = item.partition("=")
        if not name or not target:
            parser.error(f"--device takes NAME=HOST:PORT, not {item!r}")
        devices[name] = target
    if not devices:
        parser.error("name at least one --device")
    return devices
