"""The contract's enums and compound values, as short Python names, and their proto forms.

Every enum here is an IntEnum whose values are the landscape.v1 numbers, so a member can be
put straight into a request. Lengths and angles are in the device's units (GetUnits; the
default is meters and radians); every reply that carries them names its units.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field
from typing import Sequence

from landscape.v1 import types_pb2


class Frame(enum.IntEnum):
    """Seed section 6 ReferenceFrame: where a move's values are expressed."""
    JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME            # joint values, joint 1 first
    BASE = types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME    # x y z roll pitch yaw, robot base
    WORLD = types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME  # ... in the world frame
    TOOL = types_pb2.REFERENCE_FRAME_TOOL_FRAME              # ... in the current tool frame


class Motion(enum.IntEnum):
    """Seed section 6 MotionType: how the arm interpolates."""
    JOINT = types_pb2.MOTION_TYPE_JOINT_MOTION
    STRAIGHT = types_pb2.MOTION_TYPE_STRAIGHT_MOTION
    SLEW = types_pb2.MOTION_TYPE_SLEW_MOTION
    CIRCULAR = types_pb2.MOTION_TYPE_CIRCULAR_MOTION


class Offset(enum.IntEnum):
    """Seed section 6 OffsetType."""
    ABSOLUTE = types_pb2.OFFSET_TYPE_ABSOLUTE_DATA
    RELATIVE = types_pb2.OFFSET_TYPE_RELATIVE_DATA


class SpeedType(enum.IntEnum):
    """Seed section 6: percent of maximum, or linear / angular units per second."""
    PERCENT = types_pb2.SPEED_TYPE_PERCENT_SPEED
    LINEAR = types_pb2.SPEED_TYPE_LINEAR_SPEED
    ANGULAR = types_pb2.SPEED_TYPE_ANGULAR_SPEED


class AccelType(enum.IntEnum):
    """Seed section 6: percent of maximum, or linear / angular units per second squared."""
    PERCENT = types_pb2.ACCEL_TYPE_PERCENT_ACCEL
    LINEAR = types_pb2.ACCEL_TYPE_LINEAR_ACCEL
    ANGULAR = types_pb2.ACCEL_TYPE_ANGULAR_ACCEL


class LinearUnit(enum.IntEnum):
    INCHES = types_pb2.LINEAR_UNIT_INCHES
    FEET = types_pb2.LINEAR_UNIT_FEET
    METERS = types_pb2.LINEAR_UNIT_METERS
    CENTIMETERS = types_pb2.LINEAR_UNIT_CENTIMETERS
    MILLIMETERS = types_pb2.LINEAR_UNIT_MILLIMETERS


class AngularUnit(enum.IntEnum):
    DEGREES = types_pb2.ANGULAR_UNIT_DEGREES
    RADIANS = types_pb2.ANGULAR_UNIT_RADIANS


class DeviceState(enum.IntEnum):
    """The seed's states (DESIGN.md section 4), as the leaf state GetDeviceState reports."""
    IDLE = types_pb2.DEVICE_STATE_IDLE
    UNLOCKED = types_pb2.DEVICE_STATE_UNLOCKED
    INACTIVE = types_pb2.DEVICE_STATE_INACTIVE
    RESTING = types_pb2.DEVICE_STATE_RESTING
    MOVING = types_pb2.DEVICE_STATE_MOVING
    PAUSED = types_pb2.DEVICE_STATE_PAUSED
    ERROR = types_pb2.DEVICE_STATE_ERROR


@dataclass(frozen=True)
class Pose:
    """A Cartesian pose: x, y, z in the device's linear units; roll, pitch, yaw fixed-axis X-Y-Z
    in its angular units, R = Rz(yaw) Ry(pitch) Rx(roll)."""
    x: float = 0.0
    y: float = 0.0
    z: float = 0.0
    roll: float = 0.0
    pitch: float = 0.0
    yaw: float = 0.0

    def to_pb(self) -> types_pb2.Pose:
        return types_pb2.Pose(x=self.x, y=self.y, z=self.z, roll=self.roll, pitch=self.pitch,
                              yaw=self.yaw)

    @classmethod
    def from_pb(cls, pose: types_pb2.Pose) -> "Pose":
        return cls(pose.x, pose.y, pose.z, pose.roll, pose.pitch, pose.yaw)

    def values(self) -> list[float]:
        """[x, y, z, roll, pitch, yaw], the order of a move's values."""
        return [self.x, self.y, self.z, self.roll, self.pitch, self.yaw]


@dataclass(frozen=True)
class TagPoint:
    """Seed 3.5.1 tag_struct: one point of a path. `values` are the joints (JOINT frame, one
    per joint) or x, y, z, roll, pitch, yaw (Cartesian frames), in the device's units.
    time_delay in seconds; transition_speed, speed and accel in percent of maximum (0: stop
    at the point / the set speed / the set acceleration)."""
    values: Sequence[float]
    tag_name: str = ""
    tag_index: int = 0
    time_delay: float = 0.0
    transition_speed: float = 0.0
    speed: float = 0.0
    accel: float = 0.0
    aux_commands: Sequence[str] = field(default_factory=tuple)

    def check(self, frame: Frame) -> None:
        """ValueError unless the point fits `frame` (a Cartesian point has 6 values)."""
        if frame is not Frame.JOINT and len(self.values) != 6:
            raise ValueError(f"a Cartesian point has 6 values (x y z roll pitch yaw), "
                             f"got {len(self.values)}")

    def to_pb(self, frame: Frame) -> types_pb2.TagStruct:
        common = dict(tag_name=self.tag_name, tag_index=self.tag_index,
                      time_delay=self.time_delay, transition_speed=self.transition_speed,
                      speed=self.speed, accel=self.accel, aux_commands=list(self.aux_commands))
        if frame is Frame.JOINT:
            return types_pb2.TagStruct(joint_values=list(self.values), **common)
        self.check(frame)
        x, y, z, roll, pitch, yaw = self.values
        return types_pb2.TagStruct(x=x, y=y, z=z, roll=roll, pitch=pitch, yaw=yaw, **common)


def units_label(units: types_pb2.Units) -> str:
    """E.g. "meters, radians", for people."""
    return (f"{LinearUnit(units.linear).name.lower()}, "
            f"{AngularUnit(units.angular).name.lower()}") if units.linear and units.angular else ""
