"""CRCL poses (a point and the X and Z axes) <-> the device's x, y, z, roll, pitch, yaw, and
CRCL's workstation frame <-> the robot's base frame.

The device's orientation is fixed-axis X-Y-Z, R = Rz(yaw) Ry(pitch) Rx(roll) (DESIGN.md
section 6), pinocchio's rpy; CRCL's XAxis and ZAxis are the first and third columns of R.
Values here are SI (m, rad); units.py converts at the edge. A frame is the six values of CRCL's
frame in the base frame (workstation.py).
"""
from __future__ import annotations

import functools
import math

import numpy as np
import pinocchio as pin

from landscape.gateway import model as m
from landscape.gateway.units import CrclUnits


def rotation(x_axis: m.Vector, z_axis: m.Vector) -> np.ndarray:
    """3x3 rotation with these X and Z axes (re-orthonormalised: Z kept, X made normal to it)."""
    z = np.array([z_axis.i, z_axis.j, z_axis.k], dtype=float)
    z /= np.linalg.norm(z)
    x = np.array([x_axis.i, x_axis.j, x_axis.k], dtype=float)
    x -= (x @ z) * z
    x /= np.linalg.norm(x)
    return np.column_stack([x, np.cross(z, x), z])


def crcl_si(pose: m.Pose, units: CrclUnits) -> np.ndarray:
    """(6,) x, y, z (m), roll, pitch, yaw (rad) of a CRCL pose given in `units` (in CRCL's
    frame)."""
    p = pose.point
    rpy = pin.rpy.matrixToRpy(rotation(pose.x_axis, pose.z_axis))
    return np.array([units.length_si(p.x), units.length_si(p.y), units.length_si(p.z), *rpy])


def matrix(values: np.ndarray) -> np.ndarray:
    """4x4 (m) of SI x, y, z, roll, pitch, yaw."""
    out = np.eye(4)
    out[:3, :3] = pin.rpy.rpyToMatrix(*values[3:6])
    out[:3, 3] = values[:3]
    return out


def from_matrix(t: np.ndarray) -> np.ndarray:
    return np.concatenate([t[:3, 3], pin.rpy.matrixToRpy(t[:3, :3])])


@functools.lru_cache(maxsize=32)
def frame_matrices(frame: tuple[float, ...]) -> tuple[np.ndarray, np.ndarray]:
    """(CRCL's frame in the base, the base in CRCL's frame), 4x4 each, of a frame's values."""
    there = matrix(np.array(frame, dtype=float))
    return there, np.linalg.inv(there)


def to_base(values: np.ndarray, frame: tuple[float, ...]) -> np.ndarray:
    """(6,) SI pose in CRCL's frame -> the same pose in the robot's base frame."""
    return from_matrix(frame_matrices(frame)[0] @ matrix(values))


def to_workstation(values: np.ndarray, frame: tuple[float, ...]) -> np.ndarray:
    """(6,) SI pose in the base frame -> the same pose in CRCL's frame."""
    return from_matrix(frame_matrices(frame)[1] @ matrix(values))


def point_to_base(point: np.ndarray, frame: tuple[float, ...]) -> np.ndarray:
    """(3,) m in CRCL's frame -> in the base frame."""
    there = frame_matrices(frame)[0]
    return there[:3, :3] @ point + there[:3, 3]


def axes(values: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(point m, X axis, Z axis) of SI x, y, z, roll, pitch, yaw."""
    r = pin.rpy.rpyToMatrix(*values[3:6])
    return np.asarray(values[:3], dtype=float), r[:, 0], r[:, 2]


def deviation(goal: np.ndarray, actual: np.ndarray) -> tuple[np.ndarray, float, float]:
    """Per-axis position error (m, (3,)) and the angles (rad) between the X axes and the Z axes
    of two SI poses."""
    gp, gx, gz = axes(goal)
    ap, ax, az = axes(actual)
    return (np.abs(ap - gp), math.acos(max(-1.0, min(1.0, float(gx @ ax)))),
            math.acos(max(-1.0, min(1.0, float(gz @ az)))))
