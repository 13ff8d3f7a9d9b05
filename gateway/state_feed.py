"""The device's live state, kept current for every CRCL connection of the gateway.

GetStatus is answered from the latest sample of StateService.StreamState (one stream per
gateway, in the world frame, m and rad), never by a round trip per poll. While the stream is
down, status says why and how old its last sample is (past STALE_AFTER), and motions fail
rather than judge their end on it; the stream is reopened every RETRY_PERIOD.
"""
from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import dataclass, field

import grpc
import numpy as np

from landscape.gateway.errors import CrclError
from landscape.v1 import state_service_pb2, state_service_pb2_grpc, types_pb2

log = logging.getLogger(__name__)

RETRY_PERIOD = 2.0          # s between attempts to (re)open the stream
OPEN_TIMEOUT = 5.0          # s for the device to accept a stream with new sensors
STALE_AFTER = 1.0           # s without a new sample (100 at the default rate): state is old

_LINEAR_M = {types_pb2.LINEAR_UNIT_INCHES: 0.0254, types_pb2.LINEAR_UNIT_FEET: 0.3048,
             types_pb2.LINEAR_UNIT_METERS: 1.0, types_pb2.LINEAR_UNIT_CENTIMETERS: 0.01,
             types_pb2.LINEAR_UNIT_MILLIMETERS: 0.001}
_ANGULAR_RAD = {types_pb2.ANGULAR_UNIT_DEGREES: np.pi / 180.0, types_pb2.ANGULAR_UNIT_RADIANS: 1.0}


@dataclass(frozen=True, eq=False)
class LiveState:
    """One sample of the device, SI: joints rad (6,), rad/s (6,), N*m (6,) or empty; the tool
    tip in the world frame as x, y, z (m), roll, pitch, yaw (rad). Each sample is its own
    (compared and hashed by identity: status.py keeps what it made of the newest ones)."""

    sequence: int
    joint_positions: np.ndarray
    tool_pose: np.ndarray
    device_state: int                     # types_pb2.DeviceState
    joint_velocities: np.ndarray = field(default_factory=lambda: np.zeros(0))
    joint_torques: np.ndarray = field(default_factory=lambda: np.zeros(0))
    command_id: str = ""
    end_effector: str = ""
    end_effector_state: str = ""
    sensors: dict[str, tuple[float, ...]] = field(default_factory=dict)
    received: float = 0.0                 # time.monotonic() when it arrived
    time: float = 0.0                     # unix s of the controller cycle it was taken in


def _si(units: types_pb2.Units, joints, pose: types_pb2.Pose) -> tuple[np.ndarray, np.ndarray]:
    """Joints (rad) and pose (m, rad) from values in `units`."""
    scale_l = _LINEAR_M.get(units.linear, 1.0)
    scale_a = _ANGULAR_RAD.get(units.angular, 1.0)
    return (np.asarray(joints, dtype=float) * scale_a,
            np.array([pose.x * scale_l, pose.y * scale_l, pose.z * scale_l,
                      pose.roll * scale_a, pose.pitch * scale_a, pose.yaw * scale_a]))


def _from_sample(sample: state_service_pb2.StateSample) -> LiveState:
    joints, pose = _si(sample.units, sample.joint_positions, sample.tool_pose)
    scale_a = _ANGULAR_RAD.get(sample.units.angular, 1.0)
    return LiveState(
        sequence=sample.sequence, joint_positions=joints, tool_pose=pose,
        device_state=sample.device_state,
        joint_velocities=np.asarray(sample.joint_velocities) * scale_a,
        joint_torques=np.asarray(sample.joint_torques),
        command_id=sample.command_id, end_effector=sample.end_effector,
        end_effector_state=sample.end_effector_state,
        sensors={s.name: tuple(s.values) for s in sample.sensors}, received=time.monotonic(),
        time=sample.time.ToNanoseconds() / 1e9)


class StateFeed:
    """The newest LiveState (None until the first arrives), and a way to wait for a newer one.

    The sensors read into every sample are those any CRCL session enabled (`watch`). A set
    that grows is tried on a new stream first, which replaces the running one only once the
    device has accepted it: a sensor the stream cannot carry is refused, and the feed goes on
    as it was."""

    def __init__(self, channel, rate_hz: float):
        self.stub = state_service_pb2_grpc.StateServiceStub(channel)
        self.rate_hz = rate_hz
        self.latest: LiveState | None = None
        self.unavailable = "no state from the device yet"
        self.sensors: tuple[str, ...] = ()
        self._wanted: dict[object, frozenset[str]] = {}     # owner (a session) -> its sensors
        self._changing = asyncio.Lock()                     # one change of sensors at a time
        self._changed = asyncio.Condition()
        self._task: asyncio.Task | None = None

    async def start(self) -> None:
        self._task = asyncio.create_task(self._run(), name="crcl-state-feed")

    async def stop(self) -> None:
        if self._task:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)

    async def watch(self, owner, names) -> None:
        """Read `owner`'s sensors (with every other owner's) into every sample from now on;
        CrclError, and nothing changed, if the device's state stream cannot carry them."""
        async with self._changing:
            wanted = {**self._wanted, owner: frozenset(names)}
            if not wanted[owner]:
                del wanted[owner]
            sensors = tuple(sorted(frozenset().union(*wanted.values())))
            if sensors != self.sensors:
                first = None
                if not set(sensors) <= set(self.sensors):
                    first = await self._try(sensors)
                await self._restart(sensors, first)
            self._wanted = wanted

    async def _try(self, sensors: tuple[str, ...]):
        """A stream of these sensors, once the device has accepted it: (call, first reply)."""
        call = self.stub.StreamState(self._request(sensors))
        try:
            first = await asyncio.wait_for(call.read(), OPEN_TIMEOUT)
        except grpc.aio.AioRpcError as error:
            raise CrclError(f"the device's state stream cannot carry {', '.join(sensors)} "
                            f"({error.code().name}: {error.details()})") from None
        except BaseException:
            call.cancel()
            raise
        if first is grpc.aio.EOF:
            raise CrclError("the device's state stream ended at once")
        return call, first

    async def _restart(self, sensors: tuple[str, ...], first) -> None:
        old = self._task
        self.sensors = sensors
        self._task = asyncio.create_task(self._run(first), name="crcl-state-feed")
        if old is not None:
            old.cancel()
            await asyncio.gather(old, return_exceptions=True)

    def age(self) -> float | None:
        """Seconds since the newest sample arrived (None: there is none)."""
        return None if self.latest is None else time.monotonic() - self.latest.received

    def stale(self) -> str:
        """Why the newest sample cannot be taken for the device's present state ("" if it
        can)."""
        age = self.age()
        if age is None:
            return self.unavailable
        if age <= STALE_AFTER:
            return ""
        return f"the device's state is {age:.1f} s old ({self.unavailable or 'no new sample'})"

    async def present(self, timeout: float = 1.0) -> LiveState | None:
        """The newest sample if it is not old, else the next one to arrive within timeout;
        None if none does."""
        if not self.stale():
            return self.latest
        asked = time.monotonic()
        live = await self._first(lambda s: s.received >= asked, timeout)
        return live if live is not None and live.received >= asked else None

    async def taken_after(self, unix_s: float, timeout: float = 1.0) -> LiveState | None:
        """The first sample of a cycle at or after `unix_s` (an event's time); None if none
        comes within timeout."""
        live = await self._first(lambda s: s.time >= unix_s, timeout)
        return live if live is not None and live.time >= unix_s else None

    async def until(self, condition, timeout: float = 1.0) -> LiveState | None:
        """The first sample (the newest included) for which condition(sample) holds; None if
        none comes within timeout."""
        live = await self._first(condition, timeout)
        return live if live is not None and condition(live) else None

    async def _first(self, condition, timeout: float) -> LiveState | None:
        async with self._changed:
            try:
                await asyncio.wait_for(self._changed.wait_for(
                    lambda: self.latest is not None and condition(self.latest)), timeout)
            except asyncio.TimeoutError:
                pass
        return self.latest

    async def _publish(self, state: LiveState) -> None:
        self.latest, self.unavailable = state, ""
        async with self._changed:
            self._changed.notify_all()

    async def _run(self, opened=None) -> None:
        """Stream samples forever, reopening the stream RETRY_PERIOD after it fails; only
        cancelling the task ends it. `opened`: a stream already open, and its first reply."""
        while True:
            call, first = opened or (self.stub.StreamState(self._request(self.sensors)), None)
            opened = None
            try:
                await self._stream(call, first)
                self.unavailable = "state stream: the device ended it"
            except grpc.aio.AioRpcError as error:
                self.unavailable = f"state stream: {error.code().name}: {error.details()}"
            except Exception as error:   # noqa: BLE001 - the feed must outlive any surprise
                self.unavailable = f"state stream: {error!r}"
                log.exception("state stream")
            finally:
                call.cancel()
            log.warning("%s", self.unavailable)
            await asyncio.sleep(RETRY_PERIOD)

    async def _stream(self, call, message) -> None:
        while True:
            if message is not None and message.WhichOneof("message") == "sample":
                await self._publish(_from_sample(message.sample))
            message = await call.read()
            if message is grpc.aio.EOF:
                return

    def _request(self, sensors: tuple[str, ...]) -> state_service_pb2.StreamStateRequest:
        return state_service_pb2.StreamStateRequest(
            rate_hz=self.rate_hz, frame=types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME,
            units=types_pb2.Units(linear=types_pb2.LINEAR_UNIT_METERS,
                                  angular=types_pb2.ANGULAR_UNIT_RADIANS),
            sensors=list(sensors))
