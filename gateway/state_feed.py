"""The device's live state, kept current for every CRCL connection of the gateway.

GetStatus is answered from the latest sample of StateService.StreamState (one stream per
gateway, in the world frame, m and rad), never by a round trip per poll. While the stream is
down, status carries no joints or pose and says why; the stream is reopened every
RETRY_PERIOD.
"""
from __future__ import annotations

import asyncio
import logging
import time
from dataclasses import dataclass, field

import grpc
import numpy as np

from landscape.v1 import state_service_pb2, state_service_pb2_grpc, types_pb2

log = logging.getLogger(__name__)

RETRY_PERIOD = 2.0          # s between attempts to (re)open the stream

_LINEAR_M = {types_pb2.LINEAR_UNIT_INCHES: 0.0254, types_pb2.LINEAR_UNIT_FEET: 0.3048,
             types_pb2.LINEAR_UNIT_METERS: 1.0, types_pb2.LINEAR_UNIT_CENTIMETERS: 0.01,
             types_pb2.LINEAR_UNIT_MILLIMETERS: 0.001}
_ANGULAR_RAD = {types_pb2.ANGULAR_UNIT_DEGREES: np.pi / 180.0, types_pb2.ANGULAR_UNIT_RADIANS: 1.0}


@dataclass(frozen=True)
class LiveState:
    """One sample of the device, SI: joints rad (6,), rad/s (6,), N*m (6,) or empty; the tool
    tip in the world frame as x, y, z (m), roll, pitch, yaw (rad)."""

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
    """The newest LiveState (None until the first arrives), and a way to wait for a newer one."""

    def __init__(self, channel, rate_hz: float):
        self.stub = state_service_pb2_grpc.StateServiceStub(channel)
        self.rate_hz = rate_hz
        self.latest: LiveState | None = None
        self.unavailable = "no state from the device yet"
        self.sensors: tuple[str, ...] = ()
        self._changed = asyncio.Condition()
        self._task: asyncio.Task | None = None
        self._call = None

    async def start(self) -> None:
        self._task = asyncio.create_task(self._run(), name="crcl-state-feed")

    async def stop(self) -> None:
        if self._task:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)

    def watch_sensors(self, names: tuple[str, ...]) -> None:
        """Read these sensors into every sample from now on (the stream restarts)."""
        if tuple(sorted(names)) != self.sensors:
            self.sensors = tuple(sorted(names))
            if self._call is not None:
                self._call.cancel()

    async def newer_than(self, sequence: int, timeout: float = 1.0) -> LiveState | None:
        """The first sample after `sequence`, or the latest one if none comes within timeout."""
        return await self._first(lambda s: s.sequence > sequence, timeout)

    async def taken_after(self, unix_s: float, timeout: float = 1.0) -> LiveState | None:
        """The first sample of a cycle at or after `unix_s` (an event's time), or the latest
        one if none comes within timeout."""
        return await self._first(lambda s: s.time >= unix_s, timeout)

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

    async def _run(self) -> None:
        while True:
            try:
                await self._stream()
            except grpc.aio.AioRpcError as error:
                if error.code() is grpc.StatusCode.CANCELLED:
                    continue   # restarted for a new sensor set
                self.unavailable = f"state stream: {error.code().name}: {error.details()}"
                log.warning("%s", self.unavailable)
            await asyncio.sleep(RETRY_PERIOD)

    async def _stream(self) -> None:
        request = state_service_pb2.StreamStateRequest(
            rate_hz=self.rate_hz, frame=types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME,
            units=types_pb2.Units(linear=types_pb2.LINEAR_UNIT_METERS,
                                  angular=types_pb2.ANGULAR_UNIT_RADIANS),
            sensors=list(self.sensors))
        self._call = self.stub.StreamState(request)
        try:
            async for message in self._call:
                if message.WhichOneof("message") == "sample":
                    await self._publish(_from_sample(message.sample))
        finally:
            self._call = None
