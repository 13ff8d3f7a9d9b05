"""The device server as the gateway sees it: one grpc.aio channel, the stubs, and control.

`DeviceLink` is shared by every CRCL connection of a gateway: the channel, the live state feed
and the event router. `Control` is one CRCL session's hold on the device: an AsyncSession
(keep-alives; the device's disconnect handler if the gateway dies) that took the lock, and the
lease on every mutating call. Only one Control holds the lock at a time; the device says no to
the others.

Every call's failure becomes `DeviceRefused`, whose text names the RPC, the gRPC status and the
device's own explanation, so a CRCL client reads why in its StateDescription.
"""
from __future__ import annotations

import grpc
from google.rpc import error_details_pb2
from grpc_status import rpc_status

from landscape.client import AsyncSession, ClientTLS, open_aio_channel
from landscape.gateway.events import EventRouter
from landscape.gateway.state_feed import StateFeed
from landscape.v1 import (control_pb2, device_service_pb2_grpc, digital_io_service_pb2_grpc,
                          event_service_pb2_grpc, settings_pb2, types_pb2)

CALL_TIMEOUT = 30.0     # s; blocking device calls (activate, stop) finish well within


class DeviceRefused(Exception):
    """A device call failed; `code` is the gRPC status code, `reason` the ErrorInfo reason."""

    def __init__(self, rpc: str, code: grpc.StatusCode, details: str, reason: str = ""):
        self.rpc, self.code, self.reason = rpc, code, reason
        if code is grpc.StatusCode.UNIMPLEMENTED:
            text = f"the device does not implement {rpc} yet (UNIMPLEMENTED): {details}"
        else:
            text = f"{rpc} refused by the device ({code.name}{'/' + reason if reason else ''}): {details}"
        super().__init__(text)


def refused(rpc: str, error: grpc.aio.AioRpcError) -> DeviceRefused:
    reason = ""
    try:
        status = rpc_status.from_call(error)
        info = error_details_pb2.ErrorInfo()
        if status and status.details and status.details[0].Unpack(info):
            reason = info.reason
    except Exception:   # a status without rich details: the code and text say enough
        pass
    return DeviceRefused(rpc, error.code(), error.details() or "", reason)


class DeviceLink:
    """The gateway's channel to one device server, shared by all its CRCL connections."""

    def __init__(self, target: str, state_rate_hz: float = 100.0, tls: ClientTLS | None = None,
                 token: str | None = None):
        """tls and token: how to reach a device server that wants them (an operator's token
        at least, to lock and command)."""
        self.target = target
        self.channel = open_aio_channel(target, tls, token)
        self.device = device_service_pb2_grpc.DeviceServiceStub(self.channel)
        self.digital_io = digital_io_service_pb2_grpc.DigitalIOServiceStub(self.channel)
        self.event_service = event_service_pb2_grpc.EventServiceStub(self.channel)
        self.feed = StateFeed(self.channel, state_rate_hz)
        self.events = EventRouter(self.channel)
        self.slots: dict = {}      # rack tool -> its plate in the world (tooling.py)

    async def start(self) -> None:
        await self.feed.start()
        await self.events.start()

    async def close(self) -> None:
        await self.feed.stop()
        await self.events.stop()
        await self.channel.close()

    async def read(self, rpc: str, request, stub=None):
        """A read-only call (no lease)."""
        try:
            return await getattr(stub or self.device, rpc)(request, timeout=CALL_TIMEOUT)
        except grpc.aio.AioRpcError as error:
            raise refused(rpc, error) from None

    async def take_control(self, client_name: str) -> "Control":
        """Open a session and take the lock; DeviceRefused if another client holds it."""
        session = AsyncSession(self.channel, client_name)
        try:
            await session.open()
        except grpc.aio.AioRpcError as error:
            raise refused("SessionService.Connect", error) from None
        try:
            await session.lock()
        except grpc.aio.AioRpcError as error:
            await session.close()
            state = await self.read("GetDeviceState", control_pb2.GetDeviceStateRequest())
            holder = f" (locked by {state.lock_holder})" if state.locked else ""
            raise DeviceRefused("Lock", error.code(), f"{error.details()}{holder}") from None
        return Control(self, session)


class Control:
    """One CRCL session's lock on the device; mutating calls carry its lease."""

    def __init__(self, link: DeviceLink, session: AsyncSession):
        self.link = link
        self.session = session
        self.limits: settings_pb2.GetMaxVelocitiesResponse | None = None
        self.accel_limits: settings_pb2.GetMaxAccelerationsResponse | None = None
        self.pushed: dict[tuple[str, int], float] = {}   # device settings this session sent

    async def call(self, rpc: str, request, stub=None, timeout: float = CALL_TIMEOUT):
        try:
            return await getattr(stub or self.link.device, rpc)(
                request, metadata=self.session.metadata(), timeout=timeout)
        except grpc.aio.AioRpcError as error:
            raise refused(rpc, error) from None

    async def prepare(self) -> None:
        """After Lock: drives on, SI units on the device, and the arm's limits read once."""
        self.pushed.clear()
        await self.ensure_active()      # a second InitCanon finds the drives on
        await self.call("SetUnits", settings_pb2.SetUnitsRequest(
            linear_units=types_pb2.LINEAR_UNIT_METERS, angular_units=types_pb2.ANGULAR_UNIT_RADIANS))
        self.limits = await self.link.read("GetMaxVelocities", settings_pb2.GetMaxVelocitiesRequest())
        self.accel_limits = await self.link.read("GetMaxAccelerations",
                                                 settings_pb2.GetMaxAccelerationsRequest())

    async def state(self) -> int:
        reply = await self.link.read("GetDeviceState", control_pb2.GetDeviceStateRequest())
        return reply.state

    async def ensure_active(self) -> None:
        """Drives on if they are off (after StopMotion Immediate or Fast): the command that
        needs them is what moves the arm, as the spec asks."""
        if await self.state() == types_pb2.DEVICE_STATE_INACTIVE:
            await self.call("Activate", control_pb2.ActivateRequest())

    async def release(self) -> None:
        """EndCanon: stop, drives off, release the lock, end the session."""
        try:
            state = await self.state()
            if state in (types_pb2.DEVICE_STATE_RESTING, types_pb2.DEVICE_STATE_MOVING,
                         types_pb2.DEVICE_STATE_PAUSED):
                await self.call("Deactivate", control_pb2.DeactivateRequest())
            await self.call("Release", control_pb2.ReleaseRequest())
        finally:
            await self.session.close()

    async def close(self) -> None:
        """The connection ended: closing the session makes the device stop, deactivate and
        release (its disconnect handler)."""
        await self.session.close()
