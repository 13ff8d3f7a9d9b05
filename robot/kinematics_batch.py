"""The closed-form inverse kinematics of many poses at once, in numpy: `Kinematics.solve_batch`.

The same closed form as Kinematics' one-pose solver (kinematics.py: conventions, labels,
singular cases), on arrays: every branch of N poses in a few dozen numpy calls, which is what
Cartesian paths need (server/motion/cartesian.py). Where the one-pose solver rejects a pose
that is not a proper rigid transform, this one returns a NaN row for it.
"""
from __future__ import annotations

import math

import numpy as np

from landscape.robot.kinematics import ORTHONORMAL_TOL, REACH_TOL, SINGULAR_EPS, Kinematics

__all__ = ["solve_batch"]


def _wrap_array(a: np.ndarray) -> np.ndarray:
    """wrap_angle for float arrays, in place of a copy: (-pi, pi]."""
    w = a - math.tau * np.round(a / math.tau)
    w[w <= -math.pi] += math.tau
    return w


def _pose_ok(poses: np.ndarray) -> np.ndarray:
    """(..., 4, 4) -> (...,) bool: finite, last row (0, 0, 0, 1), rotation proper."""
    with np.errstate(invalid="ignore", over="ignore"):
        R = poses[..., :3, :3]
        ortho = np.abs(np.swapaxes(R, -1, -2) @ R - np.eye(3)).max(axis=(-1, -2))
        row = np.abs(poses[..., 3, :] - (0.0, 0.0, 0.0, 1.0)).max(axis=-1)
        finite = np.isfinite(poses).all(axis=(-1, -2))
        proper = (ortho <= ORTHONORMAL_TOL) & (np.linalg.det(R) > 0)
        return finite & proper & (row <= ORTHONORMAL_TOL)


def solve_batch(kin: Kinematics, poses, q_near=None) -> np.ndarray:
    """All solutions of many poses: (N, 4, 4) -> (N, 8, 6), branches in BRANCHES order.

    Angles wrapped to (-pi, pi], joint ranges ignored; NaN where a branch has no solution
    (out of reach) and in whole rows for poses that are not proper rigid transforms.
    q_near, (6,) or (N, 6), picks the free joints at singularities (default zeros).
    """
    P = np.asarray(poses, dtype=float)
    if P.ndim != 3 or P.shape[1:] != (4, 4):
        raise ValueError(f"poses must have shape (N, 4, 4), got {P.shape}")
    n = len(P)
    near = np.zeros((n, 6)) if q_near is None else np.broadcast_to(
        np.asarray(q_near, dtype=float), (n, 6))
    ok = _pose_ok(P)
    P = np.where(ok[:, None, None], P, np.eye(4))   # keep bad rows from raising warnings
    R, p = P[:, :3, :3], P[:, :3, 3]
    # The arm's constants as Kinematics derives them (this module is its batch half).
    form = kin.closed_form
    lat, lu, lf, au, af = form.lateral, form.upper, form.fore, form.upper_angle, form.fore_angle

    # Shoulder: axis 1 of the (N, 2) arrays is RIGHTY, LEFTY.
    c = p - form.flange * R[:, :, 2] - form.base
    r2 = c[:, 0] ** 2 + c[:, 1] ** 2
    x = np.sqrt(np.maximum(r2 - lat * lat, 0.0))
    wx = np.stack([x, -x], axis=1)
    q1 = np.arctan2(c[:, 1], c[:, 0])[:, None] - np.arctan2(lat, wx)
    q1 = np.where((r2 < SINGULAR_EPS**2)[:, None], near[:, :1], q1)
    px, pz = wx - form.shoulder_x, (c[:, 2] - form.shoulder_z)[:, None]
    d2 = px**2 + pz**2
    cos_bend = (d2 - lu * lu - lf * lf) / (2.0 * lu * lf)
    reach = ((ok & (r2 - lat * lat >= -REACH_TOL))[:, None]
             & (np.abs(cos_bend) <= 1.0 + REACH_TOL))

    # Elbow: (N, 2, 2), last axis POSITIVE, NEGATIVE.
    bend = np.arccos(np.clip(cos_bend, -1.0, 1.0))
    delta = np.stack([bend, -bend], axis=-1)
    phi2 = np.arctan2(px, pz)[..., None] - np.arctan2(lf * np.sin(delta),
                                                      lu + lf * np.cos(delta))
    phi2 = np.where((d2 < SINGULAR_EPS**2)[..., None], near[:, 1, None, None] + au, phi2)
    q2 = phi2 - au
    q3 = delta - af + au

    # Wrist: M = Ry(q2 + q3)^T Rz(q1)^T R, rows m0, a1, m2 of shape (N, 2, 2, 3), solved
    # once (wrist POSITIVE); NEGATIVE is the same wrist turned half a turn.
    c1, s1 = np.cos(q1)[..., None], np.sin(q1)[..., None]               # (N, 2, 1)
    ct, st = np.cos(q2 + q3)[..., None], np.sin(q2 + q3)[..., None]     # (N, 2, 2, 1)
    r0, r1, r2_ = R[:, None, 0, :], R[:, None, 1, :], R[:, None, 2, :]   # (N, 1, 3)
    a0 = (c1 * r0 + s1 * r1)[:, :, None, :]                            # (N, 2, 1, 3)
    a1 = (c1 * r1 - s1 * r0)[:, :, None, :]
    m0 = ct * a0 - st * r2_[:, :, None, :]                              # (N, 2, 2, 3)
    m22 = st[..., 0] * a0[..., 2] + ct[..., 0] * R[:, None, None, 2, 2]
    a12 = a1[..., 2]
    sw = np.hypot(m0[..., 2], a12)                                      # (N, 2, 2)
    singular = sw < SINGULAR_EPS
    q4 = np.where(singular, near[:, 3, None, None], np.arctan2(a12, m0[..., 2]))
    q5 = np.arctan2(sw, m22)
    c4, s4 = np.cos(q4), np.sin(q4)
    q6 = np.arctan2(c4 * a1[..., 0] - s4 * m0[..., 0], c4 * a1[..., 1] - s4 * m0[..., 1])

    # (N, shoulder, elbow, wrist, joint); wrapped to (-pi, pi] where not atan2's already.
    q = np.empty((n, 2, 2, 2, 6))
    q[..., 0] = _wrap_array(q1)[:, :, None, None]
    q[..., 1] = _wrap_array(q2)[..., None]
    q[..., 2] = _wrap_array(q3)[..., None]
    q[..., 0, 3] = q4 = _wrap_array(q4)
    q[..., 0, 4] = q5
    q[..., 0, 5] = q6
    half = np.where(singular, 0.0, math.pi)
    q[..., 1, 3] = np.where(q4 <= 0.0, q4 + half, q4 - half)
    q[..., 1, 4] = np.where(q5 < math.pi, -q5, q5)
    q[..., 1, 5] = np.where(q6 <= 0.0, q6 + half, q6 - half)
    q[~reach] = np.nan
    return q.reshape(n, 8, 6)
