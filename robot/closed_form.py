"""The closed form's constants, derived from the arm (`ClosedForm`), and the helpers of the
one-pose solver (kinematics.py): its input checks and the fitting of a solution into the joint
ranges. Plain floats throughout: numpy costs about a microsecond a scalar call.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from landscape.robot.arm import JOINT_AXES, ArmModel

ORTHONORMAL_TOL = 1e-6   # max |R^T R - I| element accepted as a rotation
SINGULAR_EPS = 1e-10     # below this sin(q5) (or distance, m) a joint is free and taken from q_near
REACH_TOL = 1e-12        # rounding slack on the reach tests: poses on the workspace boundary solve
_RANGE_TOL = 1e-10       # rad: a joint this far past its limit is clipped onto it, not rejected


class ClosedForm(NamedTuple):
    """The arm's constants in the closed form (m, rad), for both solvers (kinematics.py and its
    batch half, kinematics_batch.py):
    the J1 origin, J2 in link 1 (x, z), the arm plane's lateral offset from J1, the upper arm's
    and the forearm's lengths and their angles from z, and the wrist centre to the flange."""

    base: np.ndarray
    shoulder_x: float
    shoulder_z: float
    lateral: float
    upper: float
    upper_angle: float
    fore: float
    fore_angle: float
    flange: float

    @classmethod
    def of(cls, arm: ArmModel) -> "ClosedForm":
        """The constants of `arm`; ValueError for an arm the closed form does not fit (other
        joint axes, no spherical wrist, a zero-length link)."""
        if tuple(JOINT_AXES) != ("z", "y", "y", "z", "y", "z"):
            raise ValueError(f"unsupported joint axes {JOINT_AXES}: need z y y z y z")
        o = np.array(arm.joint_origins, dtype=float)
        # A spherical wrist: J5 on the J4 axis and J6 on the J5 origin's z line.
        if np.any(o[4, :2] != 0.0) or np.any(o[5, :2] != 0.0):
            raise ValueError("unsupported kinematics: the wrist axes do not meet in one point")
        g = o.tolist()   # plain floats: numpy scalars would slow the one-pose solver down
        ux, uz = g[2][0], g[2][2]                           # J2 -> J3, in link 2
        fx, fz = g[3][0], g[3][2] + g[4][2]                 # J3 -> wrist centre, in link 3
        upper, fore = math.hypot(ux, uz), math.hypot(fx, fz)
        if upper <= 0.0 or fore <= 0.0:
            raise ValueError("unsupported kinematics: zero-length upper arm or forearm")
        # The J1 axis passes through the base; J2 in link 1; the arm plane's offset from J1 (b);
        # the wrist centre -> flange, along z6.
        return cls(o[0], g[1][0], g[1][2], g[1][1] + g[2][1] + g[3][1], upper,
                   math.atan2(ux, uz), fore, math.atan2(fx, fz), g[5][2])


def vector6(v, name: str) -> list[float]:
    a = v if type(v) is np.ndarray and v.dtype == np.float64 else np.asarray(v, dtype=float)
    values = a.tolist() if a.shape == (6,) else None
    if values is None or not all(map(math.isfinite, values)):
        raise ValueError(f"{name} must be 6 finite values (rad), got {v!r}")
    return values


def pose_rows(pose) -> list[list[float]]:
    a = pose if type(pose) is np.ndarray and pose.dtype == np.float64 else np.asarray(
        pose, dtype=float)
    if a.shape != (4, 4):
        raise ValueError(f"a pose is a (4, 4) matrix, got shape {a.shape}")
    return a.tolist()


def is_rigid(pose: list[list[float]]) -> bool:
    """kinematics_batch._pose_ok for one pose as rows: plain floats are ~10x faster than numpy."""
    (xx, yx, zx, px), (xy, yy, zy, py), (xz, yz, zz, pz), last = pose
    # One sum is NaN or inf if any rotation or last-row entry is (or if they are too large to
    # be a rotation); the translation is checked apart, where large is still finite.
    if not (math.isfinite(xx + yx + zx + xy + yy + zy + xz + yz + zz + sum(last))
            and math.isfinite(px) and math.isfinite(py) and math.isfinite(pz)):
        return False
    tol = ORTHONORMAL_TOL
    if abs(last[0]) > tol or abs(last[1]) > tol or abs(last[2]) > tol or abs(last[3] - 1.0) > tol:
        return False
    # Columns x, y, z of R: unit length, mutually orthogonal, right-handed (z . (x cross y) > 0).
    for d in (xx * xx + xy * xy + xz * xz - 1.0, yx * yx + yy * yy + yz * yz - 1.0,
              zx * zx + zy * zy + zz * zz - 1.0, xx * yx + xy * yy + xz * yz,
              xx * zx + xy * zy + xz * zz, yx * zx + yy * zy + yz * zz):
        if abs(d) > tol:
            return False
    return zx * (xy * yz - xz * yy) + zy * (xz * yx - xx * yz) + zz * (xx * yy - xy * yx) > 0.0


def by_bound(items: list[tuple]) -> list[tuple]:
    """Two (bound, ...) items (or fewer), the smaller bound first (the first on a tie)."""
    if len(items) == 2 and items[1][0] < items[0][0]:
        return [items[1], items[0]]
    return items


def fit_range(q, near, lower, upper) -> tuple[list[float], float] | None:
    """Each joint moved by whole turns to the value closest to near within [lower, upper].

    Returns (joints, squared distance to near), or None if a joint has no value in range.
    """
    out, dist, pi = list(q), 0.0, math.pi
    for j, (a, n, lo, hi) in enumerate(zip(q, near, lower, upper)):
        if not (lo <= a <= hi and -pi <= a - n <= pi):   # else: in range and nearest already
            turned = a + math.tau * round((n - a) / math.tau)  # the turn nearest n, if in range
            if lo <= turned <= hi:
                out[j] = a = turned
                dist += (a - n) * (a - n)
                continue
            k_min = math.ceil((lo - _RANGE_TOL - a) / math.tau)
            k_max = math.floor((hi + _RANGE_TOL - a) / math.tau)
            if k_min > k_max:
                return None
            # |a + 2 pi k - n| is convex in k: clamp the unconstrained best turn into the range.
            k = min(max(round((n - a) / math.tau), k_min), k_max)
            a = out[j] = min(max(a + math.tau * k, lo), hi)
        dist += (a - n) * (a - n)
    return out, dist
