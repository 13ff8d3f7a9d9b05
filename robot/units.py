"""Units and Cartesian poses: what SetUnits chooses, and the pose <-> matrix conversions.

Inside the server everything is SI (m, rad, s) and poses are 4x4 homogeneous matrices; the
units of the last SetUnits apply only at the edge (convert.py). Orientation is fixed-axis X-Y-Z
roll, pitch, yaw: R = Rz(yaw) @ Ry(pitch) @ Rx(roll) (DESIGN.md section 6).
"""
from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np


class LinearUnit(enum.Enum):
    """The seed's linear units (3.3.1) and their size in meters."""

    INCHES = 0.0254
    FEET = 0.3048
    METERS = 1.0
    CENTIMETERS = 0.01
    MILLIMETERS = 0.001


class AngularUnit(enum.Enum):
    """The seed's angular units (3.3.1) and their size in radians."""

    DEGREES = math.pi / 180.0
    RADIANS = 1.0


@dataclass(frozen=True)
class Units:
    linear: LinearUnit = LinearUnit.METERS
    angular: AngularUnit = AngularUnit.RADIANS

    def length_to_si(self, value):
        return np.asarray(value, dtype=float) * self.linear.value

    def length_from_si(self, value):
        return np.asarray(value, dtype=float) / self.linear.value

    def angle_to_si(self, value):
        return np.asarray(value, dtype=float) * self.angular.value

    def angle_from_si(self, value):
        return np.asarray(value, dtype=float) / self.angular.value

    def pose_to_matrix(self, xyzrpy) -> np.ndarray:
        """(x, y, z, roll, pitch, yaw) in these units -> 4x4 in m."""
        v = np.asarray(xyzrpy, dtype=float)
        return pose_matrix(self.length_to_si(v[:3]), self.angle_to_si(v[3:6]))

    def matrix_to_pose(self, matrix) -> np.ndarray:
        """4x4 in m -> (x, y, z, roll, pitch, yaw) in these units."""
        xyz, rpy = pose_vector(matrix)
        return np.concatenate([self.length_from_si(xyz), self.angle_from_si(rpy)])


# rpy_matrix and matrix_rpy are ours, not pinocchio's rpy: as a pair they give back the angles
# to 1e-16 near pitch +-pi/2, where pin.rpy.rpyToMatrix then matrix_rpy lose up to 1e-4 rad, and
# pin.rpy.matrixToRpy picks other angles than our replies carry at gimbal lock and at +-pi.
def rpy_matrix(roll: float, pitch: float, yaw: float) -> np.ndarray:
    cr, sr, cp, sp, cy, sy = (math.cos(roll), math.sin(roll), math.cos(pitch), math.sin(pitch),
                              math.cos(yaw), math.sin(yaw))
    return np.array([[cy * cp, cy * sp * sr - sy * cr, cy * sp * cr + sy * sr],
                     [sy * cp, sy * sp * sr + cy * cr, sy * sp * cr - cy * sr],
                     [-sp, cp * sr, cp * cr]])


def matrix_rpy(rotation: np.ndarray) -> np.ndarray:
    """Inverse of rpy_matrix, pitch in [-pi/2, pi/2]; at pitch = +-pi/2 roll is set to 0."""
    r = rotation
    pitch = math.atan2(-r[2, 0], math.hypot(r[0, 0], r[1, 0]))
    if math.hypot(r[0, 0], r[1, 0]) < 1e-12:  # gimbal lock: only yaw -+ roll is defined
        return np.array([0.0, pitch, math.atan2(-r[0, 1], r[1, 1])])
    return np.array([math.atan2(r[2, 1], r[2, 2]), pitch, math.atan2(r[1, 0], r[0, 0])])


def pose_matrix(xyz, rpy) -> np.ndarray:
    m = np.eye(4)
    m[:3, :3] = rpy_matrix(*rpy)
    m[:3, 3] = xyz
    return m


def pose_vector(matrix) -> tuple[np.ndarray, np.ndarray]:
    m = np.asarray(matrix, dtype=float)
    return m[:3, 3].copy(), matrix_rpy(m[:3, :3])
