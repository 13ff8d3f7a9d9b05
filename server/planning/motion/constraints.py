"""The velocity and acceleration bounds TOPP-RA works with, from the limits and the path.

In the terms of topp_ra.py, along a joint path q(s) with x = (ds/dt)^2 and u = d2s/dt2:
`speed_caps` bounds x at each gridpoint (joint speeds, tool speeds); `tool_constraints` adds
the tool's linear and angular accelerations as one-sided rows ku u + kx x <= h; the pass
speeds of blended waypoints cap x around them (`pass_plateaus`). Units: rad, s; the tool in
m and rad.
"""
from __future__ import annotations

import math

import numpy as np

from .trajectory import JointPath, Limits

__all__ = ["speed_caps", "tool_constraints", "pass_plateaus", "rotation_vectors",
           "rotation_angle", "HUGE"]

HUGE = 1e300              # stands for "no bound" on x and in the stage lines (keeps loops finite)
_FD_STEP = 1e-6           # rad of s: central differences of the tool path
_TOOL_FD_STEP = 1e-4      # rad of s: second differences of the tool path (acceleration rows)
_FACES = 8                # faces of the polygon standing for a tool acceleration disk


def speed_caps(path: JointPath, grid: np.ndarray, limits: Limits, tool_path=None) -> np.ndarray:
    """(G,) the largest squared path speed x = (ds/dt)^2 each gridpoint allows by the joint
    velocity limits and, with a tool path, the tool tip's linear and angular speed limits:
    |dq_j/ds| sqrt(x) <= v_j, |dp/ds| sqrt(x) <= v_lin, |dtheta/ds| sqrt(x) <= w_max."""
    with np.errstate(divide="ignore"):
        rate = np.max(np.abs(path(grid, 1)) / limits.velocity, axis=1)   # 1 / max sqrt(x)
        if tool_path is not None and (limits.linear_velocity or limits.angular_velocity):
            lo, hi = path.path_interval
            sa, sb = np.maximum(grid - _FD_STEP, lo), np.minimum(grid + _FD_STEP, hi)
            pa, pb = tool_path(path(sa)), tool_path(path(sb))
            if limits.linear_velocity:
                dp = np.linalg.norm(pb[:, :3, 3] - pa[:, :3, 3], axis=1) / (sb - sa)
                rate = np.maximum(rate, dp / limits.linear_velocity)
            if limits.angular_velocity:
                dw = rotation_angle(pa[:, :3, :3], pb[:, :3, :3]) / (sb - sa)
                rate = np.maximum(rate, dw / limits.angular_velocity)
        return np.where(rate > 0, 1.0 / rate**2, HUGE)


def tool_constraints(path: JointPath, grid: np.ndarray, limits: Limits, tool_path=None
                     ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray] | None]:
    """The velocity bounds on x (G,) (speed_caps) and, with a tool path and a Cartesian
    acceleration limit, the tool's acceleration as one-sided rows at each gridpoint:
    (ku (G, R), kx (G, R), h (R,)) with ku u + kx x <= h, u = d2s/dt2, x = (ds/dt)^2.

    The tip's acceleration is p' u + p'' x (p' = dp/ds, p'' = d2p/ds2, from second
    differences of the tool path); the tool's angular acceleration likewise with the angular
    rates. With T = |p'| u + (e . p'') x along the tangent e and N = |p''_perp| x >= 0 across it,
    |a| <= A is the half disk T^2 + N^2 <= A^2, held by a polygon: faces at angles
    phi_k = k pi / (2 K), |T| cos phi + N sin phi <= A cos(pi / 4K) (the polygon inscribed in
    the disk), but the tangential face (phi = 0) at A itself, so that a straight line keeps
    exactly A; the disk is then exceeded by at most 0.3 % (K = 8) where N is about 7 % of A,
    which the sample check of time_path catches. The face phi = pi / 2 caps x. The curved
    faces are left out where the speed caps keep N too small for them to bind."""
    xcap = speed_caps(path, grid, limits, tool_path)
    if tool_path is None or not (limits.linear_acceleration or limits.angular_acceleration):
        return xcap, None
    h = _TOOL_FD_STEP
    poses = [tool_path(path(grid + d)) for d in (-h, 0.0, h)]   # the spline extends past its ends
    parts = []
    if limits.linear_acceleration:
        before, here, after = (T[:, :3, 3] for T in poses)
        parts.append(((after - before) / (2.0 * h), (after - 2.0 * here + before) / (h * h),
                      limits.linear_acceleration))
    if limits.angular_acceleration:
        w0 = rotation_vectors(poses[0][:, :3, :3], poses[1][:, :3, :3]) / h
        w1 = rotation_vectors(poses[1][:, :3, :3], poses[2][:, :3, :3]) / h
        parts.append((0.5 * (w0 + w1), (w1 - w0) / h, limits.angular_acceleration))
    ku, kx, bound = [], [], []
    inner = math.cos(math.pi / (4 * _FACES))
    for first, second, limit in parts:
        alpha = np.linalg.norm(first, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            tangent = np.where(alpha[:, None] > 0.0, first / alpha[:, None], 0.0)
        gamma = np.einsum("ij,ij->i", tangent, second)
        nu = np.linalg.norm(second - gamma[:, None] * tangent, axis=1)
        with np.errstate(divide="ignore"):
            xcap = np.minimum(xcap, np.where(nu > 0.0, limit * inner / nu, HUGE))
        # The first curved face is implied by the others while N <= A (cos(d/2) - cos d) / sin d.
        d = math.pi / (2 * _FACES)
        curved = np.any(nu * xcap > limit * (inner - math.cos(d)) / math.sin(d))
        for k in range(_FACES if curved else 1):
            c, s = math.cos(k * d), math.sin(k * d)
            for sign in (1.0, -1.0):
                ku.append(sign * c * alpha)
                kx.append(sign * c * gamma + s * nu)
                bound.append(limit if k == 0 else limit * inner)
    return xcap, (np.stack(ku, axis=1), np.stack(kx, axis=1), np.array(bound))


def pass_plateaus(path: JointPath, grid: np.ndarray, passing: list[tuple[float, float]],
                   limits: Limits, tool_path, hold: float) -> tuple[np.ndarray, tuple]:
    """For waypoints passed at a fraction of the maximum speed ((s, fraction) pairs, see
    time_path's pass_speeds): the grid with gridpoints added `hold` s of travel (1.5 cycles;
    a jerk filter's half window more) before and after each, and (grid indices, caps on x)
    holding the speed at the fraction over that stretch. The plateau makes the samples on
    either side of the waypoint show the speed asked for, not a V of the deceleration and
    acceleration around it."""
    s = np.array([p for p, _ in passing])
    fraction = np.array([f for _, f in passing])
    reach = hold * fraction / _pass_rate(path, s, limits, tool_path)   # rad of s
    lo, hi = path.path_interval
    ends = np.clip(np.concatenate([s - reach, s + reach]), lo, hi)
    grid = np.union1d(grid, ends)
    inside = (grid[:, None] >= (s - reach)[None]) & (grid[:, None] <= (s + reach)[None])
    at = np.flatnonzero(inside.any(axis=1))
    which = np.argmax(inside[at], axis=1)
    with np.errstate(divide="ignore"):
        xcap = (fraction[which] / _pass_rate(path, grid[at], limits, tool_path)) ** 2
    return grid, (at, np.minimum(xcap, HUGE))


def _pass_rate(path: JointPath, s: np.ndarray, limits: Limits, tool_path) -> np.ndarray:
    """(K,) the speed at path positions s (K,), as a fraction of the arm's maximum, per unit
    of ds/dt: the tip's linear speed with a tool path (where the tip moves), else the
    fastest joint against its maximum velocity."""
    joint_max = limits.velocity if limits.max_velocity is None else limits.max_velocity
    rate = np.max(np.abs(path(s, 1)) / joint_max, axis=1)
    if tool_path is not None:
        lo, hi = path.path_interval
        sa, sb = np.maximum(s - _FD_STEP, lo), np.minimum(s + _FD_STEP, hi)
        tip = np.linalg.norm(tool_path(path(sb))[:, :3, 3] - tool_path(path(sa))[:, :3, 3],
                             axis=1) / (sb - sa)
        linear_max = limits.max_linear_velocity or limits.linear_velocity or math.inf
        rate = np.where(tip > 1e-9, tip / linear_max, rate)
    return rate


def rotation_vectors(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """(K, 3) rotation vectors (axis times angle, rad, base axes) turning Ra into Rb, (K, 3, 3)
    each, for angles below pi: the axis from the skew part of Rb Ra^T, the angle from the
    chord (accurate for the small steps of a path). Numpy, not pin.log3: one call for K."""
    R = Rb @ np.swapaxes(Ra, -1, -2)
    skew = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]],
                    axis=1)                                  # 2 sin(angle) axis
    norm = np.linalg.norm(skew, axis=1)
    angle = rotation_angle(Ra, Rb)
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(norm > 0.0, angle / norm, 0.5)
    return skew * scale[:, None]


def rotation_angle(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """Angle (rad) between rotations (..., 3, 3), from the chord |Ra - Rb|_F = 2 sqrt(2) sin(a/2):
    accurate near zero, where acos of the trace is not. Numpy: pin.log3 takes one at a time."""
    chord = np.linalg.norm(Ra - Rb, axis=(-2, -1))
    return 2.0 * np.arcsin(np.minimum(1.0, chord / (2.0 * math.sqrt(2.0))))
