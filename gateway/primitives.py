"""CRCL's data primitives (DataPrimitives.xsd) and the parts of commands, as typed values.

Numbers are as sent, in the session's units when the command runs (see model.py).
"""
from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class Point:
    """A position in workstation coordinates, length units."""

    x: float
    y: float
    z: float


@dataclass(frozen=True)
class Vector:
    """A direction (unit length for the axes of a pose; checked where a pose is parsed)."""

    i: float
    j: float
    k: float


@dataclass(frozen=True)
class Rate:
    """TransSpeed / RotSpeed / TransAccel / RotAccel: either an absolute setting (length or
    angle units per second, or per second squared) or a fraction (0..1) of the maximum."""

    absolute: float | None = None
    fraction: float | None = None


@dataclass(frozen=True)
class PoseTolerance:
    """Per-axis position tolerances (length units) and axis-direction tolerances (angle units)."""

    x_point: float | None = None
    y_point: float | None = None
    z_point: float | None = None
    x_axis: float | None = None
    z_axis: float | None = None


@dataclass(frozen=True)
class PoseSettings:
    """The extra of PoseAndSetType: settings that apply only to the motion to this pose."""

    coordinated: bool
    trans_speed: Rate | None = None
    rot_speed: Rate | None = None
    trans_accel: Rate | None = None
    rot_accel: Rate | None = None
    tolerance: PoseTolerance | None = None


@dataclass(frozen=True)
class Pose:
    """PoseType: the controlled point and its X and Z axes (unit, orthogonal), workstation
    coordinates; `settings` is set for PoseAndSetType."""

    point: Point
    x_axis: Vector
    z_axis: Vector
    settings: PoseSettings | None = None


@dataclass(frozen=True)
class ParameterSetting:
    name: str
    value: str


@dataclass(frozen=True)
class JointTolerance:
    """JointPositionToleranceSettingType: joint number (from 1), tolerance in joint units."""

    joint: int
    tolerance: float


@dataclass(frozen=True)
class Guard:
    """GuardType: a sensor limit that would end a command early."""

    sensor_id: str
    limit_type: str
    limit_value: float
    sub_field: str | None = None
    recheck_time_us: int | None = None
    check_count: int | None = None
    last_check_time: int | None = None
    last_check_value: float | None = None
    require_trigger: bool | None = None
    error_on_trigger: bool | None = None


@dataclass(frozen=True)
class JointSpeedAccel:
    """Speed (joint units/s) and acceleration (joint units/s^2) towards a joint target."""

    speed: float | None = None
    accel: float | None = None


@dataclass(frozen=True)
class JointForceTorque:
    """Force or torque (force or torque units) and its rate of change (per second)."""

    setting: float | None = None
    change_rate: float | None = None


@dataclass(frozen=True)
class ActuateJoint:
    joint: int
    position: float          # angle units (every TX90 joint turns)
    details: JointSpeedAccel | JointForceTorque


@dataclass(frozen=True)
class JointReport:
    """ConfigureJointReportType: what to report for one joint."""

    joint: int
    position: bool
    torque_or_force: bool
    velocity: bool


