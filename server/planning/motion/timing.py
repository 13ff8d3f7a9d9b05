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
   follow, the arm held at rest before and after), and with a tool path the tool tip's
   linear and angular speeds and accelerations, must not exceed the limits (relative slack
   1e-9, rounding only; sample_check.py). Where they do (constraints hold at gridpoints, the
   samples fall between them), the section is slowed uniformly in time, which scales
   velocities by 1/k and accelerations by 1/k^2, and checked again. The duration is also
   rounded up to a whole number of cycles the same way. With a jerk limit, the profile is
   re-timed jerk-limited first (jerk_timing.py) and slowed down locally before uniformly.

The stage solver (topp_ra.py) is ours rather than toppra's: each stage's two-variable LP has a
closed form, computed for all stages at once in numpy, and each pass is a plain loop over the
lines that can bind. It returns what toppra (seidel solver, same grid, same discretisation)
returns -- tests/server/motion/test_timing.py checks this -- about 8-17x faster
(bench/bench_planning.py), which buys the fine grid that keeps every kind of motion within 1 %
of the time-optimal one (TOPP-RA's error shrinks only in proportion to the grid step).
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import NamedTuple

import numpy as np

from .constraints import pass_plateaus, rotation_angle, speed_caps, tool_constraints
from .jerk_timing import FilteredProfile, flat_turns, jerk_caps, slowed_where_exceeded
from .sample_check import Excess, excess_per_sample
from .topp_ra import ConstAccelProfile, topp_ra, toppra_reference
from .trajectory import JointPath, Limits, PlanningError, Trajectory

__all__ = ["time_path", "duration_lower_bound", "chord_parameters", "gridpoints", "speed_caps", "tool_constraints",
           "topp_ra",
           "ConstAccelProfile", "toppra_reference", "GRID_CHORD_TOL", "GRID_MAX_STEP",
           "GRID_MIN_POINTS", "LIMIT_SLACK"]

# Gridpoints (see `gridpoints`): chosen with bench/bench_planning.py so that every kind of
# motion stays within 1 % (0.3-0.7 % measured) of a fine-grid toppra reference while a
# 100-waypoint path plans in ~18 ms.
GRID_CHORD_TOL = 2e-4     # rad: the spline may leave the chord between gridpoints by this much
GRID_MAX_STEP = 0.05      # rad of joint-space path between gridpoints, at most
GRID_MIN_POINTS = 100     # per section between stops, at least

LIMIT_SLACK = 1e-9        # relative: sampled values may exceed a limit by this much (rounding)
_MAX_RETIMES = 8          # uniform slow-downs tried before giving up with LIMITS
_LOCAL_ROUNDS = 1         # local slow-downs of a jerk-limited section before a uniform one
_FLAT_TURNS_COST = 0.25   # of T: flat turns are tried where they cost less (a joint move,
                          # a line, an arc: under 0.03); blended paths lose T and more
_FLAT_TURNS_EXCESS = 0.01 # and kept if their samples exceed by less (a path with many turns:
                          # 4 to 20 %)
_MERGE = 1e-9             # rad: consecutive waypoints closer than this are the same point


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
    check_range(W, limits, np.arange(M))

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
    problem = section_problem(W, index, limits, dt, tool_path, pass_speeds)
    if problem is None:                                     # all one point: no motion
        return W[:1].copy(), np.zeros((1, 6)), [0] * len(W)
    path, grid, knot_at, caps, rows, keep, of_waypoint = problem
    xs = topp_ra(path, grid, limits.acceleration, caps, rows)
    profile = ConstAccelProfile(grid, xs)
    if profile.duration > max_duration:
        raise PlanningError("TOO_LONG", f"the motion would last {profile.duration:.4g} s, "
                            f"longer than the {max(max_duration, 0.0):.4g} s allowed",
                            index=int(index[0]))
    section = _Section(W, index, keep, of_waypoint, path, limits, dt, tool_path, max_duration)
    if limits.jerk is None:
        return section.sampled(profile, profile.times[knot_at])[:3]
    return _jerk_limited(section, grid, xs, caps, rows)


def section_problem(W: np.ndarray, index: np.ndarray, limits: Limits, dt: float, tool_path,
                    pass_speeds: dict[int, float] | None = None):
    """What TOPP-RA times one rest-to-rest section through waypoints W (M, 6) (their indices
    `index` in the whole, for pass_speeds' keys) with: (path, grid (G,), knot_at (M',), caps
    (G,), rows, keep (M,), of_waypoint (M,): the kept waypoint each belongs to), or None if
    the section is all one point."""
    s, keep = chord_parameters(W)
    if len(s) < 2:
        return None
    path = JointPath(s, W[keep])
    grid, knot_at = gridpoints(path)
    # The waypoint a dropped (repeated) point belongs to: the last kept one at or before it.
    of_waypoint = np.cumsum(keep) - 1
    passing = [(path.s[of_waypoint[i]], f) for i, f in
               ((int(w) - int(index[0]), f) for w, f in (pass_speeds or {}).items())
               if 0 < i < len(W) - 1]
    plateau = None
    if passing:
        hold = 1.5 * dt if limits.jerk is None else 1.5 * dt + _ramp(limits)
        grid, plateau = pass_plateaus(path, grid, passing, limits, tool_path, hold)
        knot_at = np.searchsorted(grid, path.s)
    caps, rows = tool_constraints(path, grid, limits, tool_path)
    if plateau is not None:
        at, xcap = plateau
        caps[at] = np.minimum(caps[at], xcap)
    if limits.jerk is not None:
        caps = np.minimum(caps, jerk_caps(path, grid, limits.jerk))
    return path, grid, knot_at, caps, rows, keep, of_waypoint


def _jerk_limited(section: _Section, grid: np.ndarray, xs: np.ndarray, caps: np.ndarray, rows):
    """The section re-timed jerk-limited (jerk_timing.py): TOPP-RA's profile xs (G,) filtered
    (`_filter_window`); where its samples exceed a limit, TOPP-RA planned again with lower
    limits there only (_LOCAL_ROUNDS times); what still exceeds then, slowed uniformly."""
    path, limits = section.path, section.limits
    window, raw, caps, taken = _filter_window(section, grid, xs, caps, rows)
    accelerations = np.tile(limits.acceleration, (len(grid) - 1, 1))
    for _ in range(_LOCAL_ROUNDS):
        excess = taken.excess
        if excess.stretch() <= 1.0 + LIMIT_SLACK:
            break
        caps, accelerations = slowed_where_exceeded(
            raw, window, taken.times, excess.per_sample("speed"),
            np.maximum(excess.per_sample("acceleration"), excess.per_sample("jerk")),
            caps, accelerations)
        raw = ConstAccelProfile(grid, topp_ra(path, grid, accelerations, caps, rows))
        taken = section.take(FilteredProfile(raw, window))
    return section.sampled(FilteredProfile(raw, window), taken=taken)[:3]


def _filter_window(section: _Section, grid: np.ndarray, xs: np.ndarray, caps: np.ndarray, rows):
    """(window s, the profile filtered, the caps it was planned with, it taken): over the time
    T the limits ramp the acceleration in, its turns made flat for T, where that costs little
    and its samples exceed by little (a joint move, a line); else over 2 T as it is (many
    turns: a window of 2 T spreads the largest jump of the path acceleration, from one limit
    to the other, within the jerk limit, and costs T once, not T / 2 per turn)."""
    ramp = _ramp(section.limits)
    flat_caps = np.minimum(caps, flat_turns(grid, xs, caps, ramp))
    if _time_lost(grid, xs, flat_caps) < _FLAT_TURNS_COST * ramp:
        flat = ConstAccelProfile(grid, topp_ra(section.path, grid, section.limits.acceleration,
                                               flat_caps, rows))
        taken = section.take(FilteredProfile(flat, ramp))
        if taken.excess.stretch() <= 1.0 + _FLAT_TURNS_EXCESS:
            return ramp, flat, flat_caps, taken
    raw = ConstAccelProfile(grid, xs)
    return 2.0 * ramp, raw, caps, section.take(FilteredProfile(raw, 2.0 * ramp))


def _time_lost(grid: np.ndarray, xs: np.ndarray, caps: np.ndarray) -> float:
    """s: at least what capping the squared speeds xs (G,) at caps (G,) costs (the time at
    the lower speeds, without the braking and speeding up around them)."""
    def duration(x):
        sd = np.sqrt(x)
        with np.errstate(divide="ignore"):
            return np.sum(2.0 * np.diff(grid) / (sd[:-1] + sd[1:]))
    return float(duration(np.minimum(xs, caps)) - duration(xs))


class _Taken(NamedTuple):
    """A profile sampled every dt at a uniform time stretch: positions and velocities (K, 6),
    path positions (K,), the profile's time at each sample (K,), their Excess."""
    q: np.ndarray
    v: np.ndarray
    s: np.ndarray
    times: np.ndarray
    stretch: float
    excess: Excess


class _Section:
    """Sampling a profile of one rest-to-rest section every dt, checked against the limits and
    slowed down uniformly where the samples exceed them."""

    def __init__(self, W, index, keep, of_waypoint, path: JointPath, limits: Limits, dt: float,
                 tool_path, max_duration: float):
        self.W, self.index, self.keep, self.of_waypoint = W, index, keep, of_waypoint
        self.path, self.limits, self.dt = path, limits, dt
        self.tool_path, self.max_duration = tool_path, max_duration

    def take(self, profile, stretch: float = 1.0) -> _Taken:
        """The profile (duration, sample(t) -> (s, ds/dt)) sampled every dt, slowed uniformly
        by `stretch` and then to a whole number of cycles; the samples' excess."""
        path, limits, dt, W = self.path, self.limits, self.dt, self.W
        if profile.duration * stretch > self.max_duration + dt:
            raise PlanningError("TOO_LONG", "the motion, slowed to keep the limits, would "
                                f"last longer than the {self.max_duration:.4g} s allowed",
                                index=int(self.index[0]))
        n = max(1, math.ceil(profile.duration * stretch / dt - 1e-9))
        stretch = n * dt / profile.duration                 # a whole number of cycles
        times = np.arange(n + 1) * (dt / stretch)
        s_k, sd_k = profile.sample(times)
        q, dq = path.evaluate(s_k, (0, 1))
        v = dq * (sd_k / stretch)[:, None]
        q[0], q[-1] = W[0], W[-1]                           # exact ends, at rest
        v[0] = v[-1] = 0.0
        check_range(q, limits, self.index[self.keep][path_piece(path, s_k)])
        return _Taken(q, v, s_k, times, stretch,
                      excess_per_sample(q, v, dt, limits, self.tool_path))

    def sampled(self, profile, knot_times: np.ndarray | None = None, taken: _Taken | None = None):
        """(positions (n, 6), velocities (n, 6), sample of each waypoint, stretch): the profile
        sampled (`taken` already, once) and slowed down uniformly until no sample exceeds a
        limit; a waypoint's sample is at its knot's time (knot_times, s) or, without them, the
        sample nearest to it along the path."""
        if taken is None:
            taken = self.take(profile)
        for _ in range(_MAX_RETIMES):
            excess = taken.excess.stretch()
            if excess <= 1.0 + LIMIT_SLACK:
                if knot_times is not None:
                    samples = np.rint(knot_times * (taken.stretch / self.dt)).astype(int)
                else:
                    samples = _nearest(taken.s, self.path.s)
                return taken.q, taken.v, samples[self.of_waypoint].tolist(), taken.stretch
            # The margin saves a round most times.
            taken = self.take(profile, taken.stretch * excess * (1.0 + 1e-4))
        raise PlanningError("LIMITS", "the sampled motion stays above the limits after "
                            "re-timing", index=int(self.index[0]))


def _ramp(limits: Limits) -> float:
    """s: the longest time a joint's jerk limit takes to ramp its acceleration limit up."""
    return float(np.max(limits.acceleration / limits.jerk))


def _nearest(s_k: np.ndarray, s: np.ndarray) -> np.ndarray:
    """(M,) the index of the sample of s_k (nondecreasing) nearest to each of s (M,)."""
    after = np.clip(np.searchsorted(s_k, s), 1, len(s_k) - 1)
    return np.where(s - s_k[after - 1] < s_k[after] - s, after - 1, after)


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
                turn = rotation_angle(poses[:-1, :3, :3], poses[1:, :3, :3])
                speed = max(speed, float(turn.sum()) / limits.angular_velocity)
        stop = np.zeros(len(W), dtype=bool) if stops is None else np.array(stops, dtype=bool)
        stop[0] = stop[-1] = True
        ends = np.flatnonzero(stop)
        shift = np.abs(W[ends[1:]] - W[ends[:-1]])              # per rest-to-rest section
        accel = float(np.sum(np.max(2.0 * np.sqrt(shift / limits.acceleration), axis=1)))
    return (speed, "speed") if speed >= accel else (accel, "acceleration")


def path_piece(path: JointPath, s: np.ndarray) -> np.ndarray:
    """(K,) int: the index of the knot starting the spline piece holding each s."""
    return np.clip(np.searchsorted(path.s, s, side="right") - 1, 0, len(path.s) - 2)


def check_range(q: np.ndarray, limits: Limits, where: np.ndarray) -> None:
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
