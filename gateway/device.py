"""The device as the gateway sees it: the client core's DeviceLink, and each CRCL session's
hold on it.

`CrclDevice` is shared by every CRCL connection of a gateway: the core's link (the channel;
the keeper threads where every session's keep-alives run, whatever the connections compute;
the event feed that follows commands by id; the live state stream, world frame, m and rad),
and the rack slots last seen. `Control` is one CRCL session's hold on the device: an
AsyncRobot on that link, acting for the CRCL peer ("crcl <ip:port>"), that took the lock, and
what CRCL keeps of the device (its limits, the settings this session sent). Only one Control
holds the lock at a time; the device says no to the others. Failures are the client core's
exceptions (landscape.client.errors), worded for a CRCL client by errors.describe.
"""
from __future__ import annotations

import asyncio

from landscape.client import AsyncRobot, DeviceLink, Endpoint, Identity, LandscapeError
from landscape.client.state_feed import StateFeed
from landscape.client.values import AngularUnit, LinearUnit
from landscape.gateway.errors import CrclError
from landscape.gateway.live import world_si
from landscape.v1 import settings_pb2, types_pb2

PROGRAM = "crcl-gateway"      # landscape-client on every call (identity.md)


class CrclDevice:
    def __init__(self, endpoint: Endpoint, state_rate_hz: float = 100.0):
        self.target = endpoint.target
        self.link = DeviceLink(endpoint, Identity(PROGRAM), state=world_si(state_rate_hz))
        self.slots: dict = {}      # rack tool -> its plate in the world (tooling.py)

    @property
    def feed(self) -> StateFeed:
        """The live state every connection reads."""
        return self.link.state

    async def start(self) -> None:
        await self.link.open(timeout=None)   # the feeds keep trying until the device answers

    async def close(self) -> None:
        await self.link.close()

    async def take_control(self, client_name: str, peer: str) -> "Control":
        """A session acting for `peer` that holds the lock; CrclError naming the holder if
        another client has it."""
        robot = AsyncRobot(self.link, client_name,
                           identity=self.link.identity.acting_for(f"crcl {peer}"))
        await robot.open()
        try:
            await robot.lock()
        except LandscapeError as refused:
            await robot.close()
            state = await robot.get_device_state()
            if state.locked:
                raise CrclError(f"{refused} (locked by {state.lock_holder})") from None
            raise
        return Control(robot)


class Control:
    """One CRCL session's lock on the device; `robot` is the client core's, with the lease."""

    def __init__(self, robot: AsyncRobot):
        self.robot = robot
        self.limits: settings_pb2.GetMaxVelocitiesResponse | None = None
        self.accel_limits: settings_pb2.GetMaxAccelerationsResponse | None = None
        self.pushed: dict[tuple[str, int], float] = {}   # device settings this session sent

    async def prepare(self) -> None:
        """After Lock: drives on, SI units on the device, and the arm's limits read once."""
        self.pushed.clear()
        await self.ensure_active()      # a second InitCanon finds the drives on
        await self.robot.set_units(LinearUnit.METERS, AngularUnit.RADIANS)
        self.limits = await self.robot.get_max_velocities()
        self.accel_limits = await self.robot.get_max_accelerations()

    async def state(self) -> int:
        return (await self.robot.get_device_state()).state

    async def ensure_active(self) -> None:
        """Drives on if they are off (after StopMotion Immediate or Fast): the command that
        needs them is what moves the arm, as the spec asks."""
        if await self.state() == types_pb2.DEVICE_STATE_INACTIVE:
            await self.robot.activate()

    async def release(self) -> None:
        """EndCanon: stop, drives off, release the lock, end the session."""
        try:
            state = await self.state()
            if state in (types_pb2.DEVICE_STATE_RESTING, types_pb2.DEVICE_STATE_MOVING,
                         types_pb2.DEVICE_STATE_PAUSED):
                await self.robot.deactivate()
            await self.robot.release()
        finally:
            await self.robot.close()

    async def close(self) -> None:
        """The connection ended: closing the session makes the device stop, deactivate and
        release (its disconnect handler)."""
        await asyncio.shield(self.robot.close())
