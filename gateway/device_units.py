"""The device's units (landscape.v1 Units) <-> SI: the one place the gateway converts them.

The gateway keeps everything in SI and never changes the device's units (SetUnits is every
client's setting, stored on the device): it reads them at InitCanon (the lock holds them
still) and converts what it sends; every reply and sample it reads names its own units.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

from landscape.v1 import types_pb2

# Size of one unit in SI.
_METERS = {types_pb2.LINEAR_UNIT_INCHES: 0.0254, types_pb2.LINEAR_UNIT_FEET: 0.3048,
           types_pb2.LINEAR_UNIT_METERS: 1.0, types_pb2.LINEAR_UNIT_CENTIMETERS: 0.01,
           types_pb2.LINEAR_UNIT_MILLIMETERS: 0.001}
_RADIANS = {types_pb2.ANGULAR_UNIT_DEGREES: math.pi / 180.0, types_pb2.ANGULAR_UNIT_RADIANS: 1.0}


@dataclass(frozen=True)
class DeviceUnits:
    """m per device length unit, rad per device angle unit."""

    meters: float = 1.0
    radians: float = 1.0

    @classmethod
    def of(cls, units: types_pb2.Units) -> "DeviceUnits":
        """Those a reply or sample names (unset: m and rad)."""
        return cls(_METERS.get(units.linear, 1.0), _RADIANS.get(units.angular, 1.0))

    # SI -> the device's
    def length(self, si: float) -> float:
        return si / self.meters

    def angle(self, si: float) -> float:
        return si / self.radians

    def pose(self, si: Sequence[float]) -> list[float]:
        """x, y, z (m), roll, pitch, yaw (rad) in the device's units."""
        return [v / self.meters for v in si[:3]] + [v / self.radians for v in si[3:6]]

    def joints(self, si: Sequence[float]) -> list[float]:
        return [v / self.radians for v in si]

    # the device's -> SI
    def pose_si(self, values: Sequence[float]) -> list[float]:
        return [v * self.meters for v in values[:3]] + [v * self.radians for v in values[3:6]]

    def pb_pose_si(self, pose: types_pb2.Pose) -> list[float]:
        return self.pose_si([pose.x, pose.y, pose.z, pose.roll, pose.pitch, pose.yaw])
