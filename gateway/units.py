"""CRCL's units (spec section VI): the names the Set*Units commands take, and their SI sizes.

The gateway keeps every setting in SI (m, rad, N, N*m, s) and converts at the edge, with the
units in force when a command runs or a status is written; so a unit change converts what is
already set, as the spec asks (SetLengthUnits: "existing values ... are converted").
"""
from __future__ import annotations

import math
from dataclasses import dataclass, replace

# Size of one unit in SI.
LENGTH = {"meter": 1.0, "millimeter": 0.001, "inch": 0.0254}
ANGLE = {"radian": 1.0, "degree": math.pi / 180.0}
FORCE = {"newton": 1.0, "pound": 4.4482216152605, "ounce": 0.27801385095378125}
TORQUE = {"newtonMeter": 1.0, "footPound": 1.3558179483314004}

_TABLES = {"length": LENGTH, "angle": ANGLE, "force": FORCE, "torque": TORQUE}


@dataclass(frozen=True)
class CrclUnits:
    """The units in force; the defaults are the spec's (after InitCanon)."""

    length: str = "meter"
    angle: str = "radian"
    force: str = "newton"
    torque: str = "newtonMeter"

    def with_unit(self, quantity: str, name: str) -> "CrclUnits":
        if name not in _TABLES[quantity]:
            raise ValueError(f"{name!r} is not a {quantity} unit ({', '.join(_TABLES[quantity])})")
        return replace(self, **{quantity: name})

    # value in these units -> SI, and back
    def length_si(self, value: float) -> float:
        return value * LENGTH[self.length]

    def angle_si(self, value: float) -> float:
        return value * ANGLE[self.angle]

    def length_out(self, si: float) -> float:
        return si / LENGTH[self.length]

    def angle_out(self, si: float) -> float:
        return si / ANGLE[self.angle]

    def force_out(self, si: float) -> float:
        return si / FORCE[self.force]

    def torque_out(self, si: float) -> float:
        return si / TORQUE[self.torque]

    def force_si(self, value: float) -> float:
        return value * FORCE[self.force]

    def torque_si(self, value: float) -> float:
        return value * TORQUE[self.torque]
