"""The cell's workstation, as CRCL sees it: where CRCL's coordinate frame lies, what the arm
holds, and the units a program starts in (the cell file's [gateway] section, the gateway's
--workstation-frame, --end-effector, --length-units and --angle-units).

CRCL gives every position in "the coordinate system of a workstation in which the robot is
located" (spec II). Here that frame is a pose in the robot's base frame; each CRCL session
starts with it at InitCanon, may replace it for itself (SetRobotParameters WorkstationFrame),
and never changes the device's own world frame: other clients never see it.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

import numpy as np

from landscape.gateway import poses
from landscape.gateway.units import ANGLE, LENGTH, CrclUnits

BARE = "none"          # end_effector: the flange with no tool


def pose_values(text: str) -> tuple[float, ...]:
    """Six numbers (x y z roll pitch yaw) from text, spaces or commas between; ValueError
    saying what is wrong."""
    try:
        values = tuple(float(v) for v in text.replace(",", " ").split())
    except ValueError:
        values = ()
    if len(values) != 6 or not all(math.isfinite(v) for v in values):
        raise ValueError(f"{text!r}: expected six numbers, x y z roll pitch yaw")
    return values


@dataclass(frozen=True)
class Workstation:
    """frame: x, y, z (m), roll, pitch, yaw (rad) of CRCL's frame in the robot's base frame.
    end_effector: a rack tool the arm holds from InitCanon on (fetched if need be), BARE for
    none, "" to leave the flange as it is. length_unit, angle_unit: the units a program starts
    in (units.py names)."""

    frame: tuple[float, ...] = (0.0,) * 6
    end_effector: str = ""
    length_unit: str = "meter"
    angle_unit: str = "radian"

    def __post_init__(self):
        if len(self.frame) != 6 or not all(math.isfinite(v) for v in self.frame):
            raise ValueError(f"the workstation frame is six numbers, x y z (m) roll pitch yaw "
                             f"(rad); got {self.frame!r}")
        for name, table in ((self.length_unit, LENGTH), (self.angle_unit, ANGLE)):
            if name not in table:
                raise ValueError(f"{name!r} is none of {', '.join(table)}")

    @functools.cached_property
    def matrix(self) -> np.ndarray:
        """4x4: CRCL's frame in the base frame (m)."""
        return poses.matrix(np.array(self.frame))

    def describe(self) -> str:
        x, y, z, roll, pitch, yaw = self.frame
        tool = {"": "whatever is on the flange", BARE: "the bare flange"}.get(
            self.end_effector, f"the {self.end_effector}")
        return (f"CRCL's frame at x {x:g} y {y:g} z {z:g} m, roll {roll:g} pitch {pitch:g} yaw "
                f"{yaw:g} rad in the robot's base frame; {tool} from InitCanon on; programs "
                f"start in {self.length_unit} and {self.angle_unit}")

    @property
    def units(self) -> CrclUnits:
        return CrclUnits(length=self.length_unit, angle=self.angle_unit)
