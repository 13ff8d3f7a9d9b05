"""server/planning/motion/horizon.py: a long section's TOPP-RA profile timed in stretches on a
receding horizon (issue 31 item 4), against the same section timed whole.

Every profile is judged on TOPP-RA's own terms: at each stage, the joint accelerations at both
of its ends within the limits (the interpolation scheme), the squared speed within the caps,
the speed never zero between the ends, at rest at the end."""
from __future__ import annotations

import numpy as np
import pytest

from landscape.robot.arm import arm_model
from landscape.server.planning.motion.horizon import final_until, joined, raw_in_stretches
from landscape.server.planning.motion.jerk_timing import FilteredProfile
from landscape.server.planning.motion.timing import (ConstAccelProfile, chord_parameters,
                                                     gridpoints, tool_constraints, topp_ra)
from landscape.server.planning.motion.trajectory import JointPath, Limits, PlanningError
from support import random_walk, tool_line

ARM = arm_model()
Q_HOME = np.array([0.0, 0.3, 1.4, 0.0, 0.9, 0.0])


def walk(n: int, seed: int, step: float = 0.3) -> np.ndarray:
    return random_walk(ARM, Q_HOME, n, seed, step)


def section(W, limits: Limits, tool_path=None):
    """(path, grid, caps, rows) of the rest-to-rest section through W, as time_path makes them."""
    s, keep = chord_parameters(np.asarray(W))
    path = JointPath(s, np.asarray(W)[keep])
    grid, _ = gridpoints(path)
    caps, rows = tool_constraints(path, grid, limits, tool_path)
    return path, grid, caps, rows


def braking_length(grid: np.ndarray, xs: np.ndarray) -> float:
    """rad of s: the longest stretch over which the profile's speed keeps falling."""
    longest, start = 0.0, 0
    for i in range(1, len(xs)):
        if xs[i] >= xs[i - 1]:
            start = i
        longest = max(longest, grid[i] - grid[start])
    return longest


def assert_a_valid_profile(path, grid, xs, limits: Limits, caps) -> None:
    u = np.diff(xs) / (2.0 * np.diff(grid))
    q1, q2 = path.evaluate(grid, (1, 2))
    for end in (0, 1):   # each stage's joint accelerations at its start and at its end
        at = slice(end, len(grid) - 1 + end)
        a = np.abs(q1[at] * u[:, None] + q2[at] * xs[at, None])
        assert (a / limits.acceleration).max() <= 1 + 1e-7
    assert np.all(xs <= caps * (1 + 1e-9))
    assert xs[0] == 0.0 and xs[-1] == 0.0
    assert np.all(xs[1:-1] > 0.0), "the speed drops to zero along the path"


def test_the_solver_starts_from_a_given_speed_as_the_rest_of_the_whole_profile():
    """x_start: TOPP-RA from a gridpoint of the whole optimum, at its speed there, returns the
    rest of the whole optimum (each pass is greedy over the same controllable sets)."""
    limits = Limits.scaled(ARM, 100, 100)
    path, grid, caps, _ = section(walk(12, seed=3), limits)
    whole = topp_ra(path, grid, limits.acceleration, caps)
    i = len(grid) // 3
    rest = topp_ra(path, grid[i:], limits.acceleration, caps[i:], x_start=whole[i])
    assert np.allclose(rest, whole[i:], rtol=1e-9, atol=1e-12 * whole.max())


def test_the_solver_refuses_a_start_speed_it_cannot_brake_from():
    limits = Limits.scaled(ARM, 100, 100)
    path, grid, caps, _ = section(walk(12, seed=3), limits)
    short = grid[-6:]          # five stages before the end: no room to brake from full speed
    with pytest.raises(PlanningError) as refused:
        topp_ra(path, short, limits.acceleration, caps[-6:], x_start=float(caps.max()))
    assert refused.value.reason == "LIMITS"


@pytest.mark.parametrize("seed", [1, 5, 9])
def test_with_a_horizon_past_the_braking_distance_the_timing_is_the_whole_optimum(seed):
    """The measured figure: a 60-point blended path at full speed, kept 0.5 rad at a time over
    a horizon of the longest braking in the whole profile plus the stretch: the same duration
    as the whole section's optimum within 1e-6 (the goal: 0.5 %)."""
    limits = Limits.scaled(ARM, 100, 100)
    path, grid, caps, _ = section(walk(60, seed=seed), limits)
    whole = topp_ra(path, grid, limits.acceleration, caps)
    stretch = 0.5
    horizon = braking_length(grid, whole) + stretch + 0.1
    assert horizon < 0.5 * grid[-1], "the test needs a section longer than its horizon"
    pieces = list(raw_in_stretches(path, grid, limits.acceleration, caps,
                                   stretch=stretch, horizon=horizon))
    assert len(pieces) > 5
    profile = joined(grid, pieces)
    assert len(profile.grid) == len(grid)
    assert_a_valid_profile(path, grid, profile.sd**2, limits, caps)
    assert profile.duration == pytest.approx(ConstAccelProfile(grid, whole).duration, rel=1e-6)


@pytest.mark.parametrize("horizon", [0.3, 0.6, 1.2])
def test_a_horizon_short_of_braking_is_slower_but_never_stalls(horizon):
    """A horizon too short to brake from the top speed: the arm goes slower, but every
    stretch starts from a speed it can continue from (never a refusal, never a stop between
    the ends), and the joined profile meets every constraint of the whole."""
    limits = Limits.scaled(ARM, 100, 100)
    path, grid, caps, _ = section(walk(40, seed=2), limits)
    whole = ConstAccelProfile(grid, topp_ra(path, grid, limits.acceleration, caps)).duration
    pieces = list(raw_in_stretches(path, grid, limits.acceleration, caps,
                                   stretch=horizon / 3, horizon=horizon))
    for before, after in zip(pieces, pieces[1:]):
        assert after.first == before.last and after.xs[0] == before.xs[-1]   # seams agree
    profile = joined(grid, pieces)
    assert_a_valid_profile(path, grid, profile.sd**2, limits, caps)
    assert profile.duration >= whole * (1 - 1e-9)


def test_a_straight_line_keeps_its_tool_rows_and_per_stage_limits_across_stretches():
    """Tool acceleration rows and one acceleration row per stage (what the jerk-limited
    timing lowers) are cut with the grid: the joined profile is the whole one's."""
    W, tip = tool_line(ARM, (0.5, -0.4, 0.55), 0.8, Q_HOME)
    limits = Limits.scaled(ARM, 100, 100, linear_velocity=0.5, linear_acceleration=2.0)
    path, grid, caps, rows = section(W, limits, tip)
    assert rows is not None
    accel = np.tile(limits.acceleration, (len(grid) - 1, 1))
    accel[len(accel) // 2:] *= 0.7
    whole = topp_ra(path, grid, accel, caps, rows)
    stretch = grid[-1] / 10
    horizon = braking_length(grid, whole) + stretch + 1e-3
    profile = joined(grid, list(raw_in_stretches(path, grid, accel, caps, rows,
                                                 stretch=stretch, horizon=horizon)))
    assert profile.duration == pytest.approx(ConstAccelProfile(grid, whole).duration, rel=1e-6)


def test_the_jerk_filter_is_final_up_to_where_the_kept_pieces_reach():
    """Rows can be sent as soon as their piece is timed: the filtered samples of the pieces
    kept so far are the filtered samples of the whole, up to final_until."""
    limits = Limits.scaled(ARM, 100, 100)
    path, grid, caps, _ = section(walk(30, seed=4), limits)
    pieces = list(raw_in_stretches(path, grid, limits.acceleration, caps,
                                   stretch=0.5, horizon=2.0))
    window = 0.04
    whole = FilteredProfile(joined(grid, pieces), window)
    for k in (1, len(pieces) // 2, len(pieces) - 1):
        so_far = joined(grid, pieces[:k])
        t = np.linspace(0.0, final_until(so_far), 200)
        for ours, theirs in zip(FilteredProfile(so_far, window).sample(t), whole.sample(t)):
            assert np.allclose(ours, theirs, rtol=0, atol=1e-12)
        later = np.array([final_until(so_far) + window / 2])
        assert FilteredProfile(so_far, window).sample(later)[0] != whole.sample(later)[0]


def test_bad_stretches_are_refused():
    limits = Limits.scaled(ARM, 100, 100)
    path, grid, caps, _ = section(walk(5, seed=4), limits)
    for stretch, horizon in ((0.0, 1.0), (1.0, 1.0), (2.0, 1.0)):
        with pytest.raises(ValueError):
            next(raw_in_stretches(path, grid, limits.acceleration, caps, stretch=stretch,
                                  horizon=horizon))
