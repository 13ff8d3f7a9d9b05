"""Motion settings of seed section 3.2 (speed, acceleration, tool offset, world frame, units),
validated, in SI. Immutable: a Set command builds a new value or changes nothing."""
from __future__ import annotations

import enum
import functools
import math
from dataclasses import dataclass, field, replace

import numpy as np

from landscape.server.errors import OutOfRange, ParamError
from landscape.robot.units import Units
from landscape.robot.arm import ArmModel

DEFAULT_SPEED_PERCENT = 25.0    # a cautious default for an arm nobody has configured yet
DEFAULT_ACCEL_PERCENT = 50.0
MAX_TOOL_OFFSET = 2.0           # m; no real tool for this class of arm is longer
MAX_WORLD_OFFSET = 100.0        # m

# Bounds that keep a motion's duration, sample count and memory bounded before planning starts
# (a tiny positive rate would otherwise plan a motion of years, and allocate terabytes):
# - every speed and acceleration setting is at least MIN_RATE_FRACTION of its maximum
#   (0.01 %: 0.01 % speed, 0.0002 m/s, ...);
# - one planned motion (a move, or one pass of a path with its approach and dwells) lasts at
#   most MAX_MOTION_SECONDS: at the 4 ms cycle 300,000 samples, about 29 MB of positions and
#   velocities (twice the 10-minute trajectory a cell may need); a point's dwell likewise.
MIN_RATE_FRACTION = 1e-4
MIN_PERCENT = 100.0 * MIN_RATE_FRACTION
MAX_MOTION_SECONDS = 1200.0


def finite(name: str, *values: float) -> None:
    if not all(math.isfinite(v) for v in values):
        raise ParamError(f"{name} must be a finite number, got {', '.join(map(repr, values))}")


def rate_in_range(name: str, value: float, maximum: float, unit: str = "") -> float:
    """A speed or acceleration from MIN_RATE_FRACTION of its maximum to the maximum; beyond,
    OutOfRange naming the field and its bounds."""
    finite(name, value)
    minimum = maximum * MIN_RATE_FRACTION
    if not minimum * (1 - 1e-12) <= value <= maximum * (1 + 1e-12):
        raise OutOfRange(f"{name} must be at least {minimum:g}{unit} and at most "
                         f"{maximum:g}{unit}, got {value:g}{unit}", field=name.replace(" ", "_"),
                         minimum=f"{minimum:g}{unit}", maximum=f"{maximum:g}{unit}")
    return float(value)


class Kind(enum.Enum):
    """What a speed or acceleration value means (the seed's SpeedType and AccelType)."""

    PERCENT = "percent"    # of the maximum, for joint and Cartesian moves
    LINEAR = "linear"      # m/s or m/s^2 of the tool tip, for Cartesian moves
    ANGULAR = "angular"    # rad/s or rad/s^2 of the tool, for Cartesian moves


@dataclass(frozen=True)
class MotionSettings:
    """What the set commands set; lengths m, angles rad, times s."""

    arm: ArmModel
    speed_percent: float = DEFAULT_SPEED_PERCENT
    accel_percent: float = DEFAULT_ACCEL_PERCENT
    linear_speed: float = math.nan      # m/s for Cartesian moves; nan: the arm's maximum
    angular_speed: float = math.nan     # rad/s
    linear_accel: float = math.nan      # m/s^2
    angular_accel: float = math.nan     # rad/s^2
    tool_offset: np.ndarray = field(default_factory=lambda: np.eye(4))   # tool tip in flange
    world_frame: np.ndarray = field(default_factory=lambda: np.eye(4))   # world in base
    units: Units = Units()

    @functools.cached_property
    def base_in_world(self) -> np.ndarray:
        """The inverse of world_frame (4x4): maps base poses into the world; computed once per
        settings (reads convert every pose with it)."""
        return np.linalg.inv(self.world_frame)

    def __post_init__(self):
        for name, default in (("linear_speed", self.arm.max_linear_velocity),
                              ("angular_speed", self.arm.max_angular_velocity),
                              ("linear_accel", self.arm.max_linear_acceleration),
                              ("angular_accel", self.arm.max_angular_acceleration)):
            if math.isnan(getattr(self, name)):
                object.__setattr__(self, name, default)

    # -- seed 3.2.1, values already in SI
    def with_speed(self, kind: Kind, value: float) -> "MotionSettings":
        return {Kind.PERCENT: self.with_speed_percent, Kind.LINEAR: self.with_linear_speed,
                Kind.ANGULAR: self.with_angular_speed}[kind](value)

    def with_accel(self, kind: Kind, value: float) -> "MotionSettings":
        return {Kind.PERCENT: self.with_accel_percent, Kind.LINEAR: self.with_linear_accel,
                Kind.ANGULAR: self.with_angular_accel}[kind](value)

    def with_speed_percent(self, value: float) -> "MotionSettings":
        return replace(self, speed_percent=rate_in_range("percent speed", value, 100.0, " %"))

    def with_linear_speed(self, value: float) -> "MotionSettings":
        return replace(self, linear_speed=rate_in_range(
            "linear speed", value, self.arm.max_linear_velocity, " m/s"))

    def with_angular_speed(self, value: float) -> "MotionSettings":
        return replace(self, angular_speed=rate_in_range(
            "angular speed", value, self.arm.max_angular_velocity, " rad/s"))

    def with_accel_percent(self, value: float) -> "MotionSettings":
        return replace(self, accel_percent=rate_in_range("percent accel", value, 100.0, " %"))

    def with_linear_accel(self, value: float) -> "MotionSettings":
        return replace(self, linear_accel=rate_in_range(
            "linear accel", value, self.arm.max_linear_acceleration, " m/s^2"))

    def with_angular_accel(self, value: float) -> "MotionSettings":
        return replace(self, angular_accel=rate_in_range(
            "angular accel", value, self.arm.max_angular_acceleration, " rad/s^2"))

    def with_tool_offset(self, matrix: np.ndarray) -> "MotionSettings":
        return replace(self, tool_offset=_checked_frame("tool offset", matrix, MAX_TOOL_OFFSET))

    def with_world_frame(self, matrix: np.ndarray) -> "MotionSettings":
        return replace(self, world_frame=_checked_frame("world frame", matrix, MAX_WORLD_OFFSET))

    def with_units(self, units: Units) -> "MotionSettings":
        return replace(self, units=units)

    # -- what the get commands report (seed 3.3.1)
    @property
    def joint_velocities(self) -> np.ndarray:
        return np.array(self.arm.max_velocity) * self.speed_percent / 100.0

    @property
    def joint_accelerations(self) -> np.ndarray:
        return np.array(self.arm.max_acceleration) * self.accel_percent / 100.0

    @property
    def joint_jerks(self) -> np.ndarray:
        """The jerk limits with the acceleration percent (the ramps keep their duration)."""
        return np.array(self.arm.max_jerk) * self.accel_percent / 100.0


def _checked_frame(name: str, matrix: np.ndarray, max_offset: float) -> np.ndarray:
    m = np.asarray(matrix, dtype=float)
    finite(name, *m.ravel())
    distance = math.hypot(*m[:3, 3])     # no overflow (and no warning) for huge offsets
    if distance > max_offset:
        raise OutOfRange(f"{name} is {distance:g} m from its origin; at most {max_offset:g} m",
                         field=name.replace(" ", "_"), maximum=f"{max_offset:g} m")
    m = m.copy()
    m.flags.writeable = False
    return m
