"""What one CRCL session has set, in SI, and what it asked status to report.

InitCanon starts from these defaults (the units and the workstation frame are the cell's,
workstation.py: the spec's meter and radian unless the cell says otherwise; the rates are the
device's cautious defaults: a quarter of the maximum speed, half the maximum acceleration; the
end tolerances DEFAULT_END_TOLERANCE and DEFAULT_JOINT_TOLERANCE). They are the session's
alone: nothing here is stored on the device.
"""
from __future__ import annotations

from dataclasses import dataclass, field

from landscape.gateway import model as m
from landscape.gateway.units import CrclUnits

JOINTS = 6    # the TX90


@dataclass(frozen=True)
class SiRate:
    """A speed or acceleration: absolute in m or rad per second (squared), or a fraction of
    the arm's maximum."""

    absolute: float | None = None
    fraction: float | None = None

    def value(self, maximum: float) -> float:
        """In SI, at most `maximum` (the robot may go slower than asked, never faster)."""
        wanted = self.absolute if self.absolute is not None else self.fraction * maximum
        return min(wanted, maximum)


def rate_si(rate: m.Rate, scale: float) -> SiRate:
    """A CRCL rate in SI; `scale` is the size of the session's length or angle unit."""
    if rate.absolute is not None:
        return SiRate(absolute=rate.absolute * scale)
    return SiRate(fraction=rate.fraction)


@dataclass(frozen=True)
class ToleranceSi:
    """A pose tolerance in SI (m per axis, rad between axes); None: not constrained."""

    x: float | None = None
    y: float | None = None
    z: float | None = None
    x_axis: float | None = None
    z_axis: float | None = None

    def over(self, base: "ToleranceSi") -> "ToleranceSi":
        """These limits, with `base`'s where these have none."""
        return ToleranceSi(*(own if own is not None else b for own, b in zip(
            (self.x, self.y, self.z, self.x_axis, self.z_axis),
            (base.x, base.y, base.z, base.x_axis, base.z_axis))))


# What counts as reached when no SetEndPoseTolerance or SetDefaultJointPositionsTolerances
# said (CRCL names no default): 1 mm per axis, 1 mrad between axes and per joint (1 mrad is
# 1 mm at the arm's 1 m reach). Far above where an arm settles (the simulated TX90 ends within
# 1e-7 m and rad, a real one within its 0.03 mm repeatability and its controller's in-position
# window), far below a wrong end (a preempted or stopped move, a pose read from old state).
DEFAULT_END_TOLERANCE = ToleranceSi(0.001, 0.001, 0.001, 0.001, 0.001)
DEFAULT_JOINT_TOLERANCE = 0.001   # rad


def tolerance_si(t: m.PoseTolerance, units: CrclUnits) -> ToleranceSi:
    length = lambda v: None if v is None else units.length_si(v)
    angle = lambda v: None if v is None else units.angle_si(v)
    return ToleranceSi(length(t.x_point), length(t.y_point), length(t.z_point),
                       angle(t.x_axis), angle(t.z_axis))


@dataclass
class Reporting:
    """ConfigureStatusReport and ConfigureJointReports: what GetStatus includes."""

    joints: bool = True
    pose: bool = True
    gripper: bool = True
    settings: bool = False
    sensors: bool = True
    guards: bool = False
    # joint number -> (position, torque or force, velocity); by default every joint's position
    joint_reports: dict[int, tuple[bool, bool, bool]] = field(
        default_factory=lambda: {j: (True, False, False) for j in range(1, JOINTS + 1)})


@dataclass
class CrclSettings:
    units: CrclUnits = CrclUnits()
    frame: tuple[float, ...] = (0.0,) * 6     # CRCL's frame in the base: x y z m, rpy rad
    trans_speed: SiRate = SiRate(fraction=0.25)
    rot_speed: SiRate = SiRate(fraction=0.25)
    trans_accel: SiRate = SiRate(fraction=0.5)
    rot_accel: SiRate = SiRate(fraction=0.5)
    end_tolerance: ToleranceSi = DEFAULT_END_TOLERANCE
    intermediate_tolerance: ToleranceSi = ToleranceSi()
    joint_tolerances: dict[int, float] = field(default_factory=dict)      # joint -> rad
    coordinated: bool = True
    end_effector_setting: float | None = None
    end_effector_parameters: dict[str, str] = field(default_factory=dict)
    robot_parameters: dict[str, str] = field(default_factory=dict)
    reported_parameters: set[str] = field(default_factory=set)
    sensors: set[str] = field(default_factory=set)
    grippers_disabled: set[str] = field(default_factory=set)
    reporting: Reporting = field(default_factory=Reporting)
