"""Time-optimal timing of a joint path under joint velocity/acceleration and tool speed limits.

`time_path` turns waypoints into a `Trajectory` sampled every dt:

1. The path between two stops is the natural C2 cubic spline through its waypoints,
   parametrised by the joint-space chord length s (rad); the arm is at rest at every stop and
   passes the other waypoints without slowing to zero.
2. TOPP-RA (Pham & Pham 2018, "A new approach to time-optimal path parameterization based on
   reachability analysis") finds the largest squared path speed x = (ds/dt)^2 at gridpoints
   along s: a backward pass computes the controllable sets K_i = [0, K_i^max], a forward pass
   takes the greatest reachable x at each gridpoint. Acceleration constraints use toppra's
   "interpolation" discretisation (each stage's constant path acceleration u must satisfy the
   joint acceleration limits at both of its ends), velocity limits bound x at each gridpoint.
3. Between gridpoints u is constant (toppra's ParametrizeConstAccel), so s(t) is known in
   closed form and is sampled every dt, vectorised.
4. The samples are CHECKED: joint velocities, forward-difference accelerations (what
   Trajectory.accelerations() gives), second differences of the positions (what the drives
   follow, the arm held at rest before and after), and with a tool path the tool tip's forward-difference
   linear and angular speeds, must not exceed the limits (relative slack 1e-9, rounding only).
   Where they do (constraints hold at gridpoints, the samples fall between them), the section
   is slowed uniformly in time, which scales velocities by 1/k and accelerations by 1/k^2, and
   checked again. The duration is also rounded up to a whole number of cycles the same way.

Why our own stage solver rather than toppra's: with only box joint constraints and speed caps,
each stage's two-variable LP has a closed form (eliminate u, Fourier-Motzkin): the part that
does not depend on the next stage is computed for all stages at once in numpy, and each pass
is a plain loop over lines. It returns what toppra (seidel solver, same grid, same
discretisation) returns -- tests/server/motion/test_timing.py checks this -- 14-20x faster
(bench/bench_planning.py), which buys the fine grid that keeps the duration within ~0.5% of
the time-optimal one (TOPP-RA's error shrinks only in proportion to the grid step).
toppra itself (slow to import: it pulls in matplotlib and scipy) is used only as the
reference, by `toppra_reference`.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence

import numpy as np

from .trajectory import JointPath, Limits, PlanningError, Trajectory

__all__ = ["time_path", "duration_lower_bound", "chord_parameters", "gridpoints", "speed_caps", "tool_constraints",
           "topp_ra",
           "ConstAccelProfile", "toppra_reference", "GRID_CHORD_TOL", "GRID_MAX_STEP",
           "GRID_MIN_POINTS", "LIMIT_SLACK"]

# Gridpoints (see `gridpoints`): chosen with bench/bench_planning.py so that the duration stays
# within ~0.5% of a fine-grid toppra reference while a 100-waypoint path plans in ~15 ms.
GRID_CHORD_TOL = 2e-4     # rad: the spline may leave the chord between gridpoints by this much
GRID_MAX_STEP = 0.05      # rad of joint-space path between gridpoints, at most
GRID_MIN_POINTS = 100     # per section between stops, at least

LIMIT_SLACK = 1e-9        # relative: sampled values may exceed a limit by this much (rounding)
_MAX_RETIMES = 8          # uniform slow-downs tried before giving up with LIMITS
_MERGE = 1e-9             # rad: consecutive waypoints closer than this are the same point
_HUGE = 1e300             # stands for "no bound" in the stage lines (keeps the loops finite)
_FD_STEP = 1e-6           # rad of s: central differences of the tool path
_A_FLOOR = 1e-9           # |dq_j/ds| below this: the joint's acceleration row ignores u
_PAIR_I, _PAIR_J = np.triu_indices(12, 1)   # the 66 pairs of a stage's 12 acceleration rows
_BLOCK = 8192             # stages per block of the pair computation (~4 MB per temporary)
_TOOL_FD_STEP = 1e-4      # rad of s: second differences of the tool path (acceleration rows)
_FACES = 8                # faces of the polygon standing for a tool acceleration disk


def time_path(waypoints, limits: Limits, dt: float, *, stops: Sequence[bool] | None = None,
              tool_path: Callable[[np.ndarray], np.ndarray] | None = None,
              max_duration: float = math.inf,
              pass_speeds: dict[int, float] | None = None) -> Trajectory:
    """Time-optimal timing with TOPP-RA of the geometric joint path through the waypoints.

    waypoints (M, 6) rad, M >= 1 (a straight line in joint space for M = 2); limits: joint
    velocity and acceleration (and, with tool_path, tool speeds; with position_min/max, the
    joint ranges every sample must keep); dt (s): the sample period (the cycle, 0.004).

    stops (M,) bools: True where the arm comes to rest (the ends always do); between stops the
    path is a C2 spline through the waypoints and the speed never drops to zero at them.
    tool_path: q (K, 6) -> tool poses (K, 4, 4) in a fixed frame, m (e.g.
    cartesian.tool_pose(kin, tcp)); with it limits.linear_velocity / angular_velocity bound the
    tool tip's speed. Pass it for dense Cartesian paths (straight lines, arcs).

    max_duration (s): a bound checked on the timing before anything is sampled, so that
    the samples (duration / dt of them) stay bounded whatever the limits.
    pass_speeds: {waypoint index: fraction in (0, 1]} for waypoints passed without stopping:
    the speed there is at most that fraction of the arm's maximum, and exactly it when the
    path and the limits allow reaching it (TOPP-RA takes the greatest speed the cap admits).
    The speed is the tool tip's linear speed against limits.max_linear_velocity with a tool
    path (when the tip moves there), else the fastest joint against its maximum velocity
    (limits.max_velocity; without them, against the limits themselves).

    Returns a Trajectory starting and ending at rest exactly at the first and last waypoints,
    with marks (sample, waypoint) for every waypoint. Raises PlanningError("OUT_OF_JNT_RANGE",
    index=i) if waypoint i, or the spline after it, leaves the joint range,
    PlanningError("LIMITS") if no timing meets the limits, PlanningError("TOO_LONG") past
    max_duration; ValueError for malformed input.
    """
    W = np.array(waypoints, dtype=float)
    if W.ndim != 2 or W.shape[1] != 6 or len(W) < 1:
        raise ValueError(f"waypoints must have shape (M >= 1, 6), got {W.shape}")
    if not np.all(np.isfinite(W)):
        raise ValueError("waypoints must be finite")
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be positive, got {dt!r}")
    M = len(W)
    stop = np.zeros(M, dtype=bool) if stops is None else np.array(stops, dtype=bool)
    if stop.shape != (M,):
        raise ValueError(f"stops must have one flag per waypoint ({M}), got {stop.shape}")
    stop[0] = stop[-1] = True
    _check_range(W, limits, np.arange(M))

    positions, velocities, marks = [W[:1]], [np.zeros((1, 6))], [(0, 0)]
    ends = np.flatnonzero(stop)
    budget = max_duration
    for a, b in zip(ends[:-1], ends[1:]):
        q, v, knot_samples = _time_section(W[a:b + 1], np.arange(a, b + 1), limits, dt,
                                           tool_path, budget, pass_speeds or {})
        budget -= (len(q) - 1) * dt
        offset = sum(len(p) for p in positions) - 1
        positions.append(q[1:])
        velocities.append(v[1:])
        marks.extend((offset + k, int(i)) for k, i in zip(knot_samples[1:], range(a + 1, b + 1)))
    return Trajectory(dt, np.concatenate(positions), np.concatenate(velocities), tuple(marks))


def _time_section(W: np.ndarray, index: np.ndarray, limits: Limits, dt: float, tool_path,
                  max_duration: float = math.inf, pass_speeds: dict[int, float] | None = None):
    """One rest-to-rest section: (positions (n, 6), velocities (n, 6), sample of each waypoint)."""
    s, keep = chord_parameters(W)
    if len(s) < 2:                                          # all one point: no motion
        return W[:1].copy(), np.zeros((1, 6)), [0] * len(W)
    path = JointPath(s, W[keep])
    grid, knot_at = gridpoints(path)
    # The waypoint a dropped (repeated) point belongs to: the last kept one at or before it.
    of_waypoint = np.cumsum(keep) - 1
    passing = [(path.s[of_waypoint[i]], f) for i, f in
               ((int(w) - int(index[0]), f) for w, f in (pass_speeds or {}).items())
               if 0 < i < len(W) - 1]
    plateau = None
    if passing:
        grid, plateau = _pass_plateaus(path, grid, passing, limits, tool_path, dt)
        knot_at = np.searchsorted(grid, path.s)
    caps, rows = tool_constraints(path, grid, limits, tool_path)
    if plateau is not None:
        at, xcap = plateau
        caps[at] = np.minimum(caps[at], xcap)
    xs = topp_ra(path, grid, limits.acceleration, caps, rows)
    profile = ConstAccelProfile(grid, xs)
    if profile.duration > max_duration:
        raise PlanningError("TOO_LONG", f"the motion would last {profile.duration:.4g} s, "
                            f"longer than the {max(max_duration, 0.0):.4g} s allowed",
                            index=int(index[0]))
    knot_times = profile.times[knot_at]

    stretch = 1.0
    for _ in range(_MAX_RETIMES):
        if profile.duration * stretch > max_duration + dt:
            raise PlanningError("TOO_LONG", "the motion, slowed to keep the limits, would last "
                                f"longer than the {max_duration:.4g} s allowed",
                                index=int(index[0]))
        n = max(1, math.ceil(profile.duration * stretch / dt - 1e-9))
        stretch = n * dt / profile.duration                 # a whole number of cycles
        s_k, sd_k = profile.sample(np.arange(n + 1) * (dt / stretch))
        q, dq = path.evaluate(s_k, (0, 1))
        v = dq * (sd_k / stretch)[:, None]
        q[0], q[-1] = W[0], W[-1]                           # exact ends, at rest
        v[0] = v[-1] = 0.0
        _check_range(q, limits, index[keep][path_piece(path, s_k)])
        excess = _excess(q, v, dt, limits, tool_path)
        if excess <= 1.0 + LIMIT_SLACK:
            samples = np.rint(knot_times * (stretch / dt)).astype(int)
            return q, v, samples[of_waypoint].tolist()
        stretch *= excess * (1.0 + 1e-4)   # the margin saves a round most times
    raise PlanningError("LIMITS", "the sampled motion stays above the limits after re-timing",
                        index=int(index[0]))


def duration_lower_bound(waypoints, limits: Limits, stops: Sequence[bool] | None = None,
                         tool_path=None) -> tuple[float, str]:
    """A cheap lower bound (s) on time_path's duration for the same arguments, and what sets
    it ("speed" or "acceleration"): no joint outruns its velocity limit between waypoints, each
    rest-to-rest section takes every joint at least 2 sqrt(|displacement| / acceleration), and
    the tool tip covers the waypoints' chords no faster than its speed limits. For refusing a
    motion that would last too long before planning it (O(M) work, no allocation past M x 6).
    """
    W = np.asarray(waypoints, dtype=float)
    if len(W) < 2:
        return 0.0, "speed"
    with np.errstate(over="ignore"):
        speed = float(np.sum(np.max(np.abs(np.diff(W, axis=0)) / limits.velocity, axis=1)))
        if tool_path is not None and (limits.linear_velocity or limits.angular_velocity):
            poses = tool_path(W)
            if limits.linear_velocity:
                tip = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
                speed = max(speed, float(tip.sum()) / limits.linear_velocity)
            if limits.angular_velocity:
                turn = _rotation_angle(poses[:-1, :3, :3], poses[1:, :3, :3])
                speed = max(speed, float(turn.sum()) / limits.angular_velocity)
        stop = np.zeros(len(W), dtype=bool) if stops is None else np.array(stops, dtype=bool)
        stop[0] = stop[-1] = True
        ends = np.flatnonzero(stop)
        shift = np.abs(W[ends[1:]] - W[ends[:-1]])              # per rest-to-rest section
        accel = float(np.sum(np.max(2.0 * np.sqrt(shift / limits.acceleration), axis=1)))
    return (speed, "speed") if speed >= accel else (accel, "acceleration")


def _pass_plateaus(path: JointPath, grid: np.ndarray, passing: list[tuple[float, float]],
                   limits: Limits, tool_path, dt: float) -> tuple[np.ndarray, tuple]:
    """For waypoints passed at a fraction of the maximum speed ((s, fraction) pairs, see
    time_path's pass_speeds): the grid with gridpoints added 1.5 cycles of travel before and
    after each, and (grid indices, caps on x) holding the speed at the fraction over that
    stretch. The plateau makes the samples on either side of the waypoint show the speed
    asked for, not a V of the deceleration and acceleration around it."""
    s = np.array([p for p, _ in passing])
    fraction = np.array([f for _, f in passing])
    reach = 1.5 * dt * fraction / _pass_rate(path, s, limits, tool_path)   # rad of s
    lo, hi = path.path_interval
    ends = np.clip(np.concatenate([s - reach, s + reach]), lo, hi)
    grid = np.union1d(grid, ends)
    inside = (grid[:, None] >= (s - reach)[None]) & (grid[:, None] <= (s + reach)[None])
    at = np.flatnonzero(inside.any(axis=1))
    which = np.argmax(inside[at], axis=1)
    with np.errstate(divide="ignore"):
        xcap = (fraction[which] / _pass_rate(path, grid[at], limits, tool_path)) ** 2
    return grid, (at, np.minimum(xcap, _HUGE))


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


def path_piece(path: JointPath, s: np.ndarray) -> np.ndarray:
    """(K,) int: the index of the knot starting the spline piece holding each s."""
    return np.clip(np.searchsorted(path.s, s, side="right") - 1, 0, len(path.s) - 2)


def _check_range(q: np.ndarray, limits: Limits, where: np.ndarray) -> None:
    """Raise OUT_OF_JNT_RANGE at the waypoint `where[k]` of the first sample k out of range."""
    if limits.position_min is None and limits.position_max is None:
        return
    lo = -np.inf if limits.position_min is None else limits.position_min - 1e-9
    hi = np.inf if limits.position_max is None else limits.position_max + 1e-9
    bad = np.any((q < lo) | (q > hi), axis=1)
    if bad.any():
        k = int(np.argmax(bad))
        joints = np.flatnonzero((q[k] < lo) | (q[k] > hi)) + 1
        raise PlanningError("OUT_OF_JNT_RANGE", f"joint(s) {joints.tolist()} out of range",
                            index=int(where[k]))


def _excess(q, v, dt, limits: Limits, tool_path) -> float:
    """Largest ratio of a sampled value to its limit, as the time stretch that would fix it:
    velocities scale with 1/k, accelerations with 1/k^2 (hence the square root)."""
    ratio = float(np.max(np.abs(v) / limits.velocity))
    if len(v) > 1:
        acc = np.abs(np.diff(v, axis=0)) / dt
        ratio = max(ratio, math.sqrt(float(np.max(acc / limits.acceleration))))
        # What the drives follow: the second difference of the positions, held at rest before
        # the first sample and after the last.
        held = np.concatenate([q[:1], q, q[-1:]])
        acc = np.abs(held[2:] - 2.0 * held[1:-1] + held[:-2]) / (dt * dt)
        ratio = max(ratio, math.sqrt(float(np.max(acc / limits.acceleration))))
    if tool_path is not None and len(q) > 1 and (limits.linear_velocity or limits.angular_velocity):
        poses = tool_path(q)
        if limits.linear_velocity:
            step = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
            ratio = max(ratio, float(step.max()) / (dt * limits.linear_velocity))
        if limits.angular_velocity:
            angle = _rotation_angle(poses[:-1, :3, :3], poses[1:, :3, :3])
            ratio = max(ratio, float(angle.max()) / (dt * limits.angular_velocity))
    if tool_path is not None and len(q) > 1 and (limits.linear_acceleration
                                                 or limits.angular_acceleration):
        poses = tool_path(q)
        # Per-cycle steps of the tip, at rest before the first sample and after the last; the
        # change of step over dt^2 is the tip's acceleration as the drives make it.
        for limit, steps in ((limits.linear_acceleration, np.diff(poses[:, :3, 3], axis=0)),
                             (limits.angular_acceleration,
                              _rotation_vectors(poses[:-1, :3, :3], poses[1:, :3, :3]))):
            if limit:
                held = np.concatenate([np.zeros((1, 3)), steps, np.zeros((1, 3))])
                acc = np.linalg.norm(np.diff(held, axis=0), axis=1) / (dt * dt)
                ratio = max(ratio, math.sqrt(float(acc.max()) / limit))
    return ratio


def _rotation_vectors(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """(K, 3) rotation vectors (axis times angle, rad, base axes) turning Ra into Rb, (K, 3, 3)
    each, for angles below pi: the axis from the skew part of Rb Ra^T, the angle from the
    chord (accurate for the small steps of a path)."""
    R = Rb @ np.swapaxes(Ra, -1, -2)
    skew = np.stack([R[:, 2, 1] - R[:, 1, 2], R[:, 0, 2] - R[:, 2, 0], R[:, 1, 0] - R[:, 0, 1]],
                    axis=1)                                  # 2 sin(angle) axis
    norm = np.linalg.norm(skew, axis=1)
    angle = _rotation_angle(Ra, Rb)
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(norm > 0.0, angle / norm, 0.5)
    return skew * scale[:, None]


def _rotation_angle(Ra: np.ndarray, Rb: np.ndarray) -> np.ndarray:
    """Angle (rad) between rotations (..., 3, 3), from the chord |Ra - Rb|_F = 2 sqrt(2) sin(a/2):
    accurate near zero, where acos of the trace is not."""
    chord = np.linalg.norm(Ra - Rb, axis=(-2, -1))
    return 2.0 * np.arcsin(np.minimum(1.0, chord / (2.0 * math.sqrt(2.0))))


# ---- the geometric path ----------------------------------------------------------------------

def chord_parameters(W: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Path parameters of waypoints (M, 6): the cumulative joint-space chord length (rad), with
    repeated points dropped. Returns (s (M',), keep (M,) bool marking the waypoints kept)."""
    step = np.linalg.norm(np.diff(W, axis=0), axis=1)
    keep = np.concatenate([[True], step > _MERGE])
    return np.concatenate([[0.0], np.cumsum(step[keep[1:]])]), keep


def gridpoints(path: JointPath, *, chord_tol: float = GRID_CHORD_TOL,
               max_step: float = GRID_MAX_STEP, min_points: int = GRID_MIN_POINTS
               ) -> tuple[np.ndarray, np.ndarray]:
    """TOPP-RA gridpoints along the path: every knot, and each knot interval cut into equal
    steps no longer than max_step, length / min_points, or sqrt(8 chord_tol / curvature)
    (the step at which the spline, of joint-space curvature |d2q/ds2|, leaves its chord by
    chord_tol). The discretisation error of TOPP-RA follows the step where the path bends.

    Returns (grid (G,), knot_at (M,) int: the grid index of each knot)."""
    s = path.s
    h = np.diff(s)
    bend = np.linalg.norm(path.knot_curvature, axis=1)
    bend = np.maximum(bend[:-1], bend[1:])                  # d2q/ds2 is linear on a piece
    step = np.minimum(min(max_step, (s[-1] - s[0]) / min_points),
                      np.sqrt(8.0 * chord_tol / np.maximum(bend, 1e-12)))
    n = np.maximum(1, np.ceil(h / step - 1e-9)).astype(int)
    piece = np.repeat(np.arange(len(h)), n)
    first = np.repeat(np.cumsum(n) - n, n)
    grid = s[piece] + (np.arange(len(piece)) - first) * (h / n)[piece]
    knot_at = np.concatenate([[0], np.cumsum(n)])
    return np.append(grid, s[-1]), knot_at


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
                dw = _rotation_angle(pa[:, :3, :3], pb[:, :3, :3]) / (sb - sa)
                rate = np.maximum(rate, dw / limits.angular_velocity)
        return np.where(rate > 0, 1.0 / rate**2, _HUGE)


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
        w0 = _rotation_vectors(poses[0][:, :3, :3], poses[1][:, :3, :3]) / h
        w1 = _rotation_vectors(poses[1][:, :3, :3], poses[2][:, :3, :3]) / h
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
            xcap = np.minimum(xcap, np.where(nu > 0.0, limit * inner / nu, _HUGE))
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


# ---- TOPP-RA ---------------------------------------------------------------------------------

def topp_ra(path: JointPath, grid: np.ndarray, acceleration: np.ndarray,
            xcap: np.ndarray, rows: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None
            ) -> np.ndarray:
    """Squared path speeds x (G,) of the time-optimal rest-to-rest motion along `path`.

    grid (G,): gridpoints from path_interval[0] to [1]; acceleration (6,) rad/s^2 (symmetric);
    xcap (G,): the velocity bounds on x (speed_caps); rows: more second-order constraints, one
    sided, per gridpoint: (ku (G, R), kx (G, R), h (R,)) with ku u + kx x <= h (the tool's
    acceleration, tool_constraints). Raises PlanningError("LIMITS") when the path cannot be
    followed (a stage with no admissible motion).

    Stage i (from s_i to s_{i+1}, length D) has the path acceleration u constant and
    x_{i+1} = x_i + 2 D u. Each row, at s_i or at s_{i+1} (where its x is x_i + 2 D u), bounds
    u from above (u <= beta x + w) or from below (u >= beta x + w); a joint-acceleration row
    |a_r u + b_r x| <= h_r does both, with beta_r = -b_r / a_r and w_r = +-h_r / |a_r|.
    Eliminating u: every lower line must stay below every upper line, which caps x (the
    acceleration limit curve); x_{i+1} <= K bounds x_i through the lower lines
    (x (1 + 2 D beta) <= K - 2 D w), and going forward the greatest next x is the least
    upper line's x_i + 2 D (beta x_i + w).
    """
    G = len(grid)
    D = np.diff(grid)[:, None]                              # (G-1, 1)
    q1, q2 = path.evaluate(grid, (1, 2))
    a = np.concatenate([q1[:-1], q1[1:] + 2.0 * D * q2[1:]], axis=1)   # (G-1, 12)
    b = np.concatenate([q2[:-1], q2[1:]], axis=1)
    h = np.concatenate([acceleration, acceleration])
    # A row with a ~ 0 hardly involves u; flooring |a| keeps the algebra finite and tends to
    # the right limit: the pairs then cap x by |b x| <= h, and its lines never bind.
    a = np.where(np.abs(a) < _A_FLOOR, np.copysign(_A_FLOOR, a), a)
    inv = 1.0 / a
    beta = -b * inv
    w = h * np.abs(inv)
    with np.errstate(divide="ignore", invalid="ignore"):
        # The acceleration limit curve: every pair of rows (w > 0: a zero gap gives inf), in
        # blocks of stages to bound the temporary memory on very long paths.
        xhi = np.empty(G - 1)
        for lo in range(0, G - 1, _BLOCK):
            wb, bb = w[lo:lo + _BLOCK], beta[lo:lo + _BLOCK]
            xhi[lo:lo + _BLOCK] = np.min((wb[:, _PAIR_I] + wb[:, _PAIR_J])
                                         / np.abs(bb[:, _PAIR_I] - bb[:, _PAIR_J]), axis=1)
        lower_beta, lower_w, upper_beta, upper_w = beta, -w, beta, w
        if rows is not None:
            lower_beta, lower_w, upper_beta, upper_w, xhi = _with_rows(
                rows, D, beta, w, xhi)
        # u >= -x / 2D (x_{i+1} >= 0) against each upper line.
        g = -1.0 / (2.0 * D) - upper_beta
        xhi = np.minimum(xhi, np.min(np.where(g > 0, upper_w / g, np.inf), axis=1))
        xhi = np.minimum(xhi, xcap[:-1])
        d = 1.0 + 2.0 * D * lower_beta                                    # x d <= K - 2 D w
        back_p = np.where(d > 0, 1.0 / d, 0.0)                            # x <= K p + q
        back_q = np.where(d > 0, np.minimum(-2.0 * D * lower_w * back_p, _HUGE), _HUGE)
        d = 1.0 + 2.0 * D * upper_beta                                    # x' <= d x + c
        c = np.minimum(2.0 * D * upper_w, _HUGE)
    if not np.all(xhi >= 0):
        raise PlanningError("LIMITS", "the path cannot be followed within the limits")

    # Backward pass: the controllable sets [0, K_i], K_{G-1} = 0 (at rest at the end). Each
    # stage's bound is the lower envelope of its lines in K_{i+1}; the loop visits only the
    # lines that can be on it (_binding_rows), mostly one or two, and skips stages with none.
    keep = _binding_rows(back_p, back_q, np.append(xhi[1:], 0.0), xhi)
    K = np.append(xhi, 0.0)
    K = _backward(K, keep, back_p, back_q)

    # Forward pass: from rest, the greatest x the next controllable set admits (again an
    # envelope of lines, in x_i over [0, K_i]).
    keep = _binding_rows(d, c, K[:-1], K[1:])
    xs = _forward(K, keep, d, c)
    xs[-1] = 0.0
    stalled = (xs[1:-1] <= 0.0)
    if stalled.any():
        raise PlanningError("LIMITS", "the path speed drops to zero at s = "
                            f"{grid[1 + int(np.argmax(stalled))]:.4g} rad")
    return xs


def _with_rows(rows, D: np.ndarray, beta: np.ndarray, w: np.ndarray, xhi: np.ndarray):
    """The joint rows' lines (beta, +-w, (S, 12)) with the one-sided rows added: (lower beta,
    lower w, upper beta, upper w) (S, 12 + 2R) and xhi (S,) capped by every new pair of a
    lower and an upper line (lower must stay below upper: (bl - bu) x <= wu - wl)."""
    ku, kx, h = rows
    # At both ends of each stage; at the end x_{i+1} = x_i + 2 D u.
    cu = np.concatenate([ku[:-1], ku[1:] + 2.0 * D * kx[1:]], axis=1)    # (S, 2R)
    cx = np.concatenate([kx[:-1], kx[1:]], axis=1)
    bound = np.broadcast_to(np.concatenate([h, h]), cu.shape)
    cu = np.where(np.abs(cu) < _A_FLOOR, np.copysign(_A_FLOOR, cu), cu)
    new_beta, offset = -cx / cu, bound / cu
    up = cu > 0
    new_upper = np.where(up, offset, np.inf)          # lines a row does not set never bind
    new_lower = np.where(up, -np.inf, offset)
    for lo in range(0, len(xhi), _BLOCK):
        part = slice(lo, lo + _BLOCK)
        bu = np.concatenate([beta[part], new_beta[part]], axis=1)
        wu = np.concatenate([w[part], new_upper[part]], axis=1)
        bl, wl = new_beta[part], new_lower[part]
        # New lower lines against every upper line, then the joint lower lines against the
        # new upper lines (joint against joint is done).
        gap = bl[:, :, None] - bu[:, None, :]
        room = wu[:, None, :] - wl[:, :, None]
        cap = np.min(np.where(gap > 0, room / gap, np.inf), axis=(1, 2))
        gap = beta[part][:, :, None] - new_beta[part][:, None, :]
        room = new_upper[part][:, None, :] + w[part][:, :, None]
        cap = np.minimum(cap, np.min(np.where(gap > 0, room / gap, np.inf), axis=(1, 2)))
        xhi[part] = np.minimum(xhi[part], cap)
    return (np.concatenate([beta, new_beta], axis=1), np.concatenate([-w, new_lower], axis=1),
            np.concatenate([beta, new_beta], axis=1), np.concatenate([w, new_upper], axis=1),
            xhi)


def _binding_rows(slope: np.ndarray, intercept: np.ndarray, upper: np.ndarray,
                  cap: np.ndarray) -> np.ndarray:
    """(S, R) bool: the lines y = slope * z + intercept (S stages, R rows) that can be the least
    one, and below the stage's cap (S,), for some z in [0, upper] (S,).

    Exact pruning: with a the least line at z = 0 and b the least at z = upper, min(a, b) is
    concave, so a line at or above it where a and b cross is at or above it everywhere on
    the interval; only a, b and lines below that point can matter."""
    upper = upper[:, None]
    at0, at1 = intercept, slope * upper + intercept
    rows = np.arange(slope.shape[0])
    a, b = np.argmin(at0, axis=1), np.argmin(at1, axis=1)
    pa, qa, pb, qb = slope[rows, a], intercept[rows, a], slope[rows, b], intercept[rows, b]
    with np.errstate(divide="ignore", invalid="ignore"):
        cross = np.clip((qb - qa) / (pa - pb), 0.0, upper[:, 0])
    cross = np.where(np.isfinite(cross), cross, 0.0)[:, None]
    below = slope * cross + intercept < (pa * cross[:, 0] + qa)[:, None]
    keep = below
    keep[rows, a] = True
    keep[rows, b] = True
    return keep & ((at0 < cap[:, None]) | (at1 < cap[:, None]))


def _backward(K: np.ndarray, keep: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """K_i = min(K_i, min over kept rows r of stage i: K_{i+1} p_r + q_r), from the end back;
    K (G,) holds the caps on entry. One flat loop over the kept rows, last stage first (a
    stage's rows are consecutive, so K_{i+1} is final when stage i's rows come)."""
    stage = np.nonzero(keep)[0][::-1].tolist()
    P, Q = p[keep][::-1].tolist(), q[keep][::-1].tolist()
    Kl = K.tolist()
    for i, pr, qr in zip(stage, P, Q):
        bound = Kl[i + 1] * pr + qr
        if bound < Kl[i]:
            Kl[i] = bound if bound > 0.0 else 0.0
    return np.array(Kl)


def _forward(K: np.ndarray, keep: np.ndarray, d: np.ndarray, c: np.ndarray) -> np.ndarray:
    """x_0 = 0, x_{i+1} = min(K_{i+1}, min over kept rows r of stage i: d_r x_i + c_r), one
    flat loop over the kept rows, first stage first."""
    stage = np.nonzero(keep)[0].tolist()
    Dl, Cl = d[keep].tolist(), c[keep].tolist()
    xs = K.tolist()
    xs[0] = 0.0
    for i, dr, cr in zip(stage, Dl, Cl):
        bound = dr * xs[i] + cr
        if bound < xs[i + 1]:
            xs[i + 1] = bound if bound > 0.0 else 0.0
    return np.array(xs)


class ConstAccelProfile:
    """s(t) from squared path speeds x (G,) at gridpoints (G,): constant path acceleration
    u_i = (x_{i+1} - x_i) / (2 (s_{i+1} - s_i)) on each stage (toppra's ParametrizeConstAccel),
    vectorised. times (G,) s: when each gridpoint is reached."""

    def __init__(self, grid: np.ndarray, xs: np.ndarray):
        self.grid = grid
        self.sd = np.sqrt(np.maximum(xs, 0.0))
        D = np.diff(grid)
        self.u = np.diff(xs) / (2.0 * D)
        with np.errstate(divide="ignore"):
            dt = 2.0 * D / (self.sd[:-1] + self.sd[1:])
        if not np.all(np.isfinite(dt)):
            raise PlanningError("LIMITS", "the path speed is zero on a stage")
        self.times = np.concatenate([[0.0], np.cumsum(dt)])

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Path position s (K,) rad and speed ds/dt (K,) rad/s at times t (K,) s."""
        i = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.u) - 1)
        r = np.maximum(t - self.times[i], 0.0)
        sd0, u = self.sd[i], self.u[i]
        sd = np.maximum(sd0 + u * r, 0.0)
        s = np.clip(self.grid[i] + r * (sd0 + 0.5 * u * r), self.grid[i], self.grid[i + 1])
        return s, sd


def toppra_reference(path: JointPath, grid: np.ndarray, limits: Limits, tool_path=None
                     ) -> np.ndarray:
    """The same problem solved by the toppra library (seidel LP solver, interpolation scheme):
    squared path speeds (G,). For tests and benchmarks; imports toppra (slow, ~2 s cold)."""
    import toppra
    import toppra.algorithm
    import toppra.constraint

    class SpeedCaps(toppra.constraint.LinearConstraint):
        """Our velocity bounds on x (joint and tool speeds) as a toppra first-order constraint."""

        def __init__(self):
            super().__init__()
            self.dof = 6

        def compute_constraint_params(self, path_, grid_, *args, **kwargs):
            caps = tool_constraints(path_, grid_, limits, tool_path)[0]
            return (None, None, None, None, None, None,
                    np.stack([np.zeros_like(caps), caps], axis=1))

    class ToolRows(toppra.constraint.LinearConstraint):
        """tool_constraints' one-sided rows: ku u + kx x <= h at each gridpoint."""

        def __init__(self):
            super().__init__()
            self.dof = 6
            self.identical = True
            self.discretization_type = interpolation

        def compute_constraint_params(self, path_, grid_, *args, **kwargs):
            ku, kx, h = tool_constraints(path_, grid_, limits, tool_path)[1]
            # A LinearConstraint discretises itself (as JointAccelerationConstraint does).
            return toppra.constraint.canlinear_colloc_to_interpolate(
                ku, kx, np.zeros_like(ku), np.eye(len(h)), h, None, None, grid_, identical=True)

    interpolation = toppra.constraint.DiscretizationType.Interpolation
    acc = toppra.constraint.JointAccelerationConstraint(limits.acceleration,
                                                        discretization_scheme=interpolation)
    constraints = [SpeedCaps(), acc]
    if tool_constraints(path, grid[:2], limits, tool_path)[1] is not None:
        constraints.append(ToolRows())
    algo = toppra.algorithm.TOPPRA(constraints, path, gridpoints=grid, solver_wrapper="seidel")
    _, sd, _ = algo.compute_parameterization(0.0, 0.0)[:3]
    if sd is None:
        raise PlanningError("LIMITS", "toppra found no parametrization")
    return np.asarray(sd) ** 2
