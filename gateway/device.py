"""The device as the gateway sees it: the client core's DeviceLink, and each CRCL session's
hold on it.

`CrclDevice` is shared by every CRCL connection of a gateway: the core's link (the channel;
the keeper threads where every session's keep-alives run, whatever the connections compute;
the event feed that follows commands by id; the live state stream, base frame, m and rad),
and the rack slots last seen. `Control` is one CRCL session's hold on the device: an
AsyncRobot on that link, acting for the CRCL peer ("crcl <ip:port>"), that took the lock, and
what CRCL keeps of the device (its units and limits, the settings this session sent and what
they were before). Only one Control holds the lock at a time; the device says no to the
others. Failures are the client core's exceptions (landscape.client.errors), worded for a
CRCL client by errors.describe.
"""
from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import dataclass

from landscape.client import (AsyncRobot, DeviceLink, Endpoint, Frame, Identity, LandscapeError,
                              Pose)
from landscape.client.aio_streams import SI_UNITS, state_request
from landscape.client.state_feed import StateFeed
from landscape.gateway.device_units import DeviceUnits
from landscape.gateway.errors import CrclError
from landscape.v1 import settings_pb2, types_pb2

log = logging.getLogger(__name__)

PROGRAM = "crcl-gateway"      # landscape-client on every call (identity.md)
ENDING_WAIT = 10.0            # s a new session waits for this gateway's sessions still ending
RETRY = 1.0                   # s at most between Lock attempts while a session ends


class CrclDevice:
    def __init__(self, endpoint: Endpoint, state_rate_hz: float = 100.0):
        self.target = endpoint.target
        # CRCL reads the base frame in m and rad (live.py)
        self.link = DeviceLink(endpoint, Identity(PROGRAM),
                               state=state_request(state_rate_hz, Frame.BASE, SI_UNITS, ()))
        self.slots: dict = {}      # rack tool -> its plate in the base frame (tooling.py)
        self._ending: set[asyncio.Future] = set()    # sessions' ends under way

    @property
    def feed(self) -> StateFeed:
        """The live state every connection reads."""
        return self.link.state

    async def start(self) -> None:
        await self.link.open(timeout=None)   # the feeds keep trying until the device answers

    async def close(self) -> None:
        await self.link.close()

    async def end(self, control: "Control") -> None:
        """A session's end (the arm stopped, its settings put back, the lock released)."""
        await self.ending(control.close())

    async def ending(self, end) -> None:
        """Run the coroutine `end` (a session ending) to its end whatever cancels the caller;
        new sessions wait for it (take_control). Counted from the call, not from its first
        step: a connection's end first cancels its running command, and a client that
        reconnected at once was refused the lock meanwhile (test_run)."""
        ending = asyncio.ensure_future(end)
        self._ending.add(ending)
        ending.add_done_callback(self._ending.discard)
        await asyncio.shield(ending)

    async def take_control(self, client_name: str, peer: str) -> "Control":
        """A session acting for `peer` that holds the lock, once this gateway's sessions still
        ending have let it go (a client that reconnects at once finds it free); CrclError
        naming the holder if another client has it."""
        if self._ending:
            await asyncio.wait(set(self._ending), timeout=ENDING_WAIT)
        robot = AsyncRobot(self.link, client_name,
                           identity=self.link.identity.acting_for(f"crcl {peer}"))
        await robot.open()
        try:
            await _lock(robot, self.feed)
        except LandscapeError as refused:
            await robot.close()
            state = await robot.get_device_state()
            if state.locked:
                raise CrclError(f"{refused} (locked by {state.lock_holder})") from None
            raise
        return Control(robot)


async def _lock(robot: AsyncRobot, feed: StateFeed) -> None:
    """Lock, waiting (up to ENDING_WAIT) for a device still bringing its last holder's session
    to an end: unlocked already, but braking and turning the drives off, so Lock is not valid
    yet (a CRCL client's InitCanon right after a lost lock). The wait is on the state feed the
    gateway reads anyway, until a sample shows the device UNLOCKED, not on GetDeviceState asked
    again and again."""
    loop = asyncio.get_running_loop()
    deadline = loop.time() + ENDING_WAIT
    ended = False      # the last refusal found the session's end over already
    while True:
        try:
            return await robot.lock()
        except LandscapeError:
            asked = time.monotonic()
            state = await robot.get_device_state()
            unlocked = state.state == types_pb2.DEVICE_STATE_UNLOCKED
            # UNLOCKED once may be the end coming between the refusal and this read (the suite
            # saw it: "not valid in state resting", then UNLOCKED): Lock once more at once.
            # UNLOCKED twice is a refusal for another reason.
            if state.locked or (unlocked and ended) or loop.time() > deadline:
                raise
            ended = unlocked
            if not unlocked:
                # A sample from after the refusal; one that misses the end (a stream down,
                # another client's Lock at once) costs a retry after RETRY, never more.
                await feed.until(
                    lambda sample: (sample.received >= asked and sample.message.device_state
                                    == types_pb2.DEVICE_STATE_UNLOCKED),
                    timeout=min(RETRY, max(deadline - loop.time(), 0.0)))


@dataclass(frozen=True)
class Limits:
    """The arm's maxima in SI: the tool tip's speed (m/s, rad/s) and acceleration (m/s^2,
    rad/s^2), and each joint's (rad/s, rad/s^2)."""

    linear_speed: float
    angular_speed: float
    linear_accel: float
    angular_accel: float
    joint_speeds: tuple[float, ...]
    joint_accels: tuple[float, ...]

    @classmethod
    def of(cls, speeds: settings_pb2.GetMaxVelocitiesResponse,
           accels: settings_pb2.GetMaxAccelerationsResponse) -> "Limits":
        v, a = DeviceUnits.of(speeds.units), DeviceUnits.of(accels.units)
        return cls(speeds.max_world_linear_velocity * v.meters,
                   speeds.max_world_angular_velocity * v.radians,
                   accels.max_world_linear_accel * a.meters,
                   accels.max_world_angular_accel * a.radians,
                   tuple(w * v.radians for w in speeds.max_joint_velocities),
                   tuple(w * a.radians for w in accels.max_joint_accels))


# A device rate setting: (rpc, SpeedType or AccelType).
Rate = tuple[str, int]
_LINEAR = {types_pb2.SPEED_TYPE_LINEAR_SPEED, types_pb2.ACCEL_TYPE_LINEAR_ACCEL}
_ANGULAR = {types_pb2.SPEED_TYPE_ANGULAR_SPEED, types_pb2.ACCEL_TYPE_ANGULAR_ACCEL}


class Control:
    """One CRCL session's lock on the device; `robot` is the client core's, with the lease.

    What the session sets on the device (rates, a tool offset) is put back as it was when the
    session ends (EndCanon, the next InitCanon, or the connection's end), so no other client
    ever finds it; the device's units are read, never set."""

    def __init__(self, robot: AsyncRobot):
        self.robot = robot
        self.units = DeviceUnits()
        self.limits: Limits | None = None
        self.pushed: dict[Rate, float] = {}      # rates this session sent, SI
        self._rates_before: dict[Rate, float] = {}
        self._offset_before: tuple[list[float], str] | None = None   # SI offset, and the tool
        self.drives_off = False         # this session turned them off

    async def prepare(self) -> None:
        """After Lock (or at a second InitCanon): the last session's settings put back, drives
        on, and the device's units, limits and rates read once."""
        await self.restore()
        await self.ensure_active()      # a second InitCanon finds the drives on
        units = await self.robot.get_units()
        self.units = DeviceUnits.of(types_pb2.Units(linear=units.linear_units,
                                                    angular=units.angular_units))
        self.limits = Limits.of(await self.robot.get_max_velocities(),
                                await self.robot.get_max_accelerations())
        speeds, accels = await self.robot.get_velocities(), await self.robot.get_accelerations()
        v, a = DeviceUnits.of(speeds.units), DeviceUnits.of(accels.units)
        self._rates_before = {
            ("SetSpeed", types_pb2.SPEED_TYPE_PERCENT_SPEED): speeds.percent_velocity,
            ("SetSpeed", types_pb2.SPEED_TYPE_LINEAR_SPEED): speeds.world_linear_velocity * v.meters,
            ("SetSpeed", types_pb2.SPEED_TYPE_ANGULAR_SPEED):
                speeds.world_angular_velocity * v.radians,
            ("SetAcceleration", types_pb2.ACCEL_TYPE_PERCENT_ACCEL): accels.percent_accel,
            ("SetAcceleration", types_pb2.ACCEL_TYPE_LINEAR_ACCEL):
                accels.world_linear_accel * a.meters,
            ("SetAcceleration", types_pb2.ACCEL_TYPE_ANGULAR_ACCEL):
                accels.world_angular_accel * a.radians}

    async def set_rate(self, rate: Rate, value: float) -> None:
        """A speed or acceleration setting (SI, or percent), unless the device has it already
        from this session."""
        if self.pushed.get(rate) == value:
            return
        self.pushed.pop(rate, None)   # unknown until the device says yes
        rpc, kind = rate
        sent = (self.units.length(value) if kind in _LINEAR else
                self.units.angle(value) if kind in _ANGULAR else value)
        if rpc == "SetSpeed":
            await self.robot.set_speed(sent, kind)
        else:
            await self.robot.set_acceleration(sent, kind)
        self.pushed[rate] = value

    async def set_tool_offset(self, offset: list[float]) -> None:
        """The controlled point in the flange frame (SI x y z roll pitch yaw)."""
        if self._offset_before is None:
            reply = await self.robot.get_tool_offsets()
            tool = (await self.robot.get_end_effector_state()).current_ee
            self._offset_before = (DeviceUnits.of(reply.units).pb_pose_si(reply.offset), tool)
        await self.robot.set_tool_offset(Pose(*self.units.pose(offset)))

    async def restore(self) -> None:
        """What this session set, as it was before; a tool offset only if the same tool is on
        the flange (a tool change set the new tool's own)."""
        for rate, value in list(self.pushed.items()):
            if rate in self._rates_before and value != self._rates_before[rate]:
                await self.set_rate(rate, self._rates_before[rate])
        self.pushed.clear()
        if self._offset_before is not None:
            offset, tool = self._offset_before
            self._offset_before = None
            if (await self.robot.get_end_effector_state()).current_ee == tool:
                await self.robot.set_tool_offset(Pose(*self.units.pose(offset)))

    async def state(self) -> int:
        return (await self.robot.get_device_state()).state

    async def ensure_active(self) -> None:
        """Drives on if they are off (this session turned them off, StopMotion Immediate or
        Fast, or the device says so): the command that needs them is what moves the arm, as
        the spec asks."""
        if self.drives_off or await self.state() == types_pb2.DEVICE_STATE_INACTIVE:
            await self.robot.activate()
        self.drives_off = False

    async def deactivate(self) -> None:
        """Drives off (Deactivate stops a motion first); already off is fine."""
        try:
            await self.robot.deactivate()
        except LandscapeError:
            if await self.state() != types_pb2.DEVICE_STATE_INACTIVE:
                raise
        self.drives_off = True

    async def release(self) -> None:
        """EndCanon: stop, drives off, the session's settings put back, the lock released,
        the session ended."""
        try:
            await self._end()
        finally:
            await self.robot.close()

    async def close(self) -> None:
        """The connection ended: as EndCanon, while the session is still the device's. The
        lock is free when this returns: a client that reconnects at once gets it (closing
        the session alone left the release to the device's disconnect handler, which a new
        session's Lock could overtake). Whatever fails, the session is closed, and the
        device's disconnect handler does the rest."""
        try:
            if self.robot.lost is None:
                await self._end()
        except LandscapeError as error:
            log.warning("ending the session on the device: %s", error)
        finally:
            await asyncio.shield(self.robot.close())

    async def _end(self) -> None:
        await self._stop()
        await self._restore_quietly()
        await self.robot.release()

    async def _stop(self) -> None:
        """A motion stopped along its path (as the device's disconnect handler stops it),
        then the drives off."""
        state = await self.state()
        if state == types_pb2.DEVICE_STATE_MOVING:
            await self.robot.stop_motion()
            state = types_pb2.DEVICE_STATE_PAUSED
        if state in (types_pb2.DEVICE_STATE_RESTING, types_pb2.DEVICE_STATE_PAUSED):
            await self.robot.deactivate()

    async def _restore_quietly(self) -> None:
        try:
            await self.restore()
        except LandscapeError as error:
            log.warning("putting back the session's device settings: %s", error)
