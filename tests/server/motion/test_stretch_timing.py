"""server/planning/motion/stretch_timing.py: a long section timed, sampled and checked stretch
by stretch (issue 31 item 4), against time_path's timing of the same section whole.

Judged where the cycle sees it: every sample of the rows given out, joined, within the
velocity, acceleration and jerk limits (sample_check: the arm at rest before and after), on
the path (each row on the section's spline), from rest at the first waypoint to rest at the
last, every waypoint marked once, in order."""
from __future__ import annotations

import numpy as np
import pytest

from landscape.robot.arm import arm_model
from landscape.robot.kinematics import Kinematics
from landscape.server.device.motion_settings import MotionSettings
from landscape.server.planning.moves import Planner
from landscape.server.planning.path_planning import plan_run, plan_run_lazily
from landscape.server.planning.paths import PathPoint, StoredPath
from landscape.server.planning.motion.sample_check import excess_per_sample
from landscape.server.planning.motion.stretch_timing import time_in_stretches
from landscape.server.planning.motion.timing import (LIMIT_SLACK, chord_parameters, time_path)
from landscape.server.planning.motion.trajectory import JointPath, Limits
from support import random_walk, tool_line

ARM = arm_model()
DT = 0.004
Q_HOME = np.array([0.0, 0.3, 1.4, 0.0, 0.9, 0.0])


def walk(n: int, seed: int, step: float = 0.3) -> np.ndarray:
    return random_walk(ARM, Q_HOME, n, seed, step)


def joined(chunks):
    q = np.concatenate([c.positions for c in chunks])
    v = np.concatenate([c.velocities for c in chunks])
    return q, v, [m for c in chunks for m in c.marks]


def assert_a_valid_section(W, q, v, marks, limits) -> None:
    excess = excess_per_sample(q, v, DT, limits)
    assert excess.stretch() <= 1.0 + LIMIT_SLACK, f"a sample at {excess.stretch():.6f}"
    assert np.array_equal(q[0], W[0]) and np.array_equal(q[-1], W[-1])
    assert not v[0].any() and not v[-1].any()
    assert [w for _, w in marks] == list(range(len(W)))
    rows = [row for row, _ in marks]
    assert rows == sorted(rows) and rows[0] == 0 and rows[-1] == len(q) - 1
    s, keep = chord_parameters(W)
    path = JointPath(s, W[keep])
    dense = path.evaluate(np.linspace(0.0, s[-1], 50_001), (0,))[0]
    gap = max(float(np.min(np.linalg.norm(dense - row, axis=1))) for row in q[::50])
    assert gap < 1e-3, f"a row {gap:.2e} rad off the path"


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_a_long_blended_section_in_stretches_keeps_every_limit_and_time_paths_time(seed):
    """A 100-point blended walk at full speed (about 20 s of motion): the rows given out
    stretch by stretch are a valid motion along the path, and last at most 0.5 % longer than
    time_path's whole-section timing (measured: see the commit message)."""
    W = walk(100, seed)
    limits = Limits.scaled(ARM, 100, 100)
    chunks = list(time_in_stretches(W, limits, DT))
    assert len(chunks) > 10
    q, v, marks = joined(chunks)
    assert_a_valid_section(W, q, v, marks, limits)
    whole = time_path(W, limits, DT)
    assert len(q) <= 1.005 * len(whole.positions)


def test_the_first_rows_come_before_the_rest_is_timed():
    """Lazy: the first chunk ends early along the path, at speed; the rest comes as asked."""
    W = walk(100, 4)
    limits = Limits.scaled(ARM, 100, 100)
    stream = time_in_stretches(W, limits, DT)
    first = next(stream)
    assert 0 < len(first.positions) < 500
    assert np.abs(first.velocities[-1]).max() > 0.1     # moving: not braking to rest there
    rest = list(stream)
    assert sum(len(c.positions) for c in rest) > 10 * len(first.positions)


def test_a_slower_setting_and_pass_speeds_hold_across_stretches():
    """Set percents and points passed at a transition speed: the stretches pass each point as
    time_path does (at the speed asked for or as fast as the path allows there)."""
    W = walk(40, 6)
    limits = Limits.scaled(ARM, 40, 30)
    passing = {i: 0.2 for i in range(1, len(W) - 1, 5)}
    q, v, marks = joined(list(time_in_stretches(W, limits, DT, pass_speeds=passing)))
    assert_a_valid_section(W, q, v, marks, limits)
    whole = time_path(W, limits, DT, pass_speeds=passing)
    assert len(q) <= 1.005 * len(whole.positions)
    def pass_speeds(v, marks):   # the fastest joint against its maximum, at each pass mark
        return [np.max(np.abs(v[row]) / ARM.max_velocity) for row, w in marks if w in passing]
    assert pass_speeds(v, marks) == pytest.approx(pass_speeds(whole.velocities, whole.marks),
                                                  rel=0.05)


def test_a_short_section_is_one_chunk_and_a_point_is_one_row():
    limits = Limits.scaled(ARM, 100, 100)
    W = np.array([Q_HOME, Q_HOME + 0.1])
    chunks = list(time_in_stretches(W, limits, DT))
    q, v, marks = joined(chunks)
    assert_a_valid_section(W, q, v, marks, limits)
    point = list(time_in_stretches(W[:1], limits, DT))
    assert len(point) == 1 and len(point[0].positions) == 1


# ---- a path run planned lazily (path_planning.plan_run_lazily) -----------------------------

def long_path(points: int, dwell_at: int) -> StoredPath:
    """A blended joint path of `points` points (passed at 50 %), a dwell in the middle."""
    W = walk(points, seed=8)
    return StoredPath("long", False, tuple(np.eye(4).ravel()), tuple(
        PathPoint(tuple(float(v) for v in q), f"p{i}", i, time_delay=0.5 if i == dwell_at else 0.0,
                  transition_speed=0.0 if i in (0, points - 1) else 50.0)
        for i, q in enumerate(W)))


def test_a_long_path_run_comes_in_chunks_labelled_as_the_whole_run():
    """Two cycles of a 60-point path with a dwell at point 30: two long stretches, each in
    chunks that continue one another (one moving segment each, every sample within the
    limits across the seams), every point's label in the same order as plan_run's, the later
    cycle reusing the first's pieces, within 0.5 % of plan_run's rows."""
    planner = Planner(Kinematics(ARM), DT)
    settings = MotionSettings(ARM)
    path = long_path(60, dwell_at=30)
    start = np.array(path.points[0].joints)
    whole = plan_run(planner, path, start, settings, 2)
    lazy = plan_run_lazily(planner, path, start, settings, 2)
    first, continues = next(lazy)
    assert not continues and len(first) < len(whole[0]) / 5     # before the rest is timed
    run = [(first, continues), *lazy]
    labels = [label for piece, _ in run for _, label in piece.marks]
    assert labels == [label for piece in whole for _, label in piece.marks]
    assert labels == [*range(60), *range(60)]
    assert sum(len(p) for p, _ in run) <= 1.005 * sum(len(p) for p in whole)
    segments = []
    for piece, continues in run:
        if continues:
            segments[-1] = (np.concatenate([segments[-1][0], piece.positions]),
                            np.concatenate([segments[-1][1], piece.velocities]))
        else:
            segments.append((piece.positions, piece.velocities))
    assert len(segments) == len(whole)       # the dwells' holds, the stretches, the way back
    limits = planner.limits(settings, None)
    for q, v in segments:
        assert excess_per_sample(q, v, DT, limits).stretch() <= 1.0 + LIMIT_SLACK
    half = len(run) // 2
    assert all(a is b for (a, _), (b, _) in zip(run[:half], run[half + 1:]))   # reused


def test_a_short_path_is_planned_whole_as_before():
    planner = Planner(Kinematics(ARM), DT)
    settings = MotionSettings(ARM)
    path = long_path(6, dwell_at=3)
    start = np.array(path.points[0].joints)
    lazy = [piece for piece, continues in plan_run_lazily(planner, path, start, settings, 1)
            if not continues]
    whole = plan_run(planner, path, start, settings, 1)
    assert len(lazy) == len(whole)
    assert all(np.array_equal(a.positions, b.positions) and a.marks == b.marks
               for a, b in zip(lazy, whole))


def test_a_straight_line_keeps_the_tool_limits_across_stretches():
    """A dense Cartesian path with the tool's speed and acceleration limits: every sample
    within them (the tool rows are cut with the grid, and lowered with the joints' limits
    where a sample exceeds: before, the slow-downs left a tool excess of 1.0007 in place and
    the section was refused)."""
    W, tip = tool_line(ARM, (0.5, -0.4, 0.55), 0.8, Q_HOME)
    limits = Limits.scaled(ARM, 100, 100, linear_velocity=1.0, linear_acceleration=3.0)
    chunks = list(time_in_stretches(W, limits, DT, tool_path=tip, stretch=0.2, horizon=1.0))
    assert len(chunks) > 2
    q, v, _ = joined(chunks)
    assert excess_per_sample(q, v, DT, limits, tip).stretch() <= 1.0 + LIMIT_SLACK
    # A line alone takes time_path's window of T with flat turns; the stretches take 2 T (a
    # long section has many turns): T (5 cycles) longer, once per section.
    ramp = round(float(np.max(limits.acceleration / limits.jerk)) / DT)
    assert len(q) <= len(time_path(W, limits, DT, tool_path=tip).positions) + ramp + 1


def test_a_long_straight_path_run_in_chunks_labels_its_points_and_keeps_the_tool_limits():
    """STRAIGHT_MOTION: the dense rows between points carry no label, the points theirs, in
    order; the joined chunks keep the tool's limits (the default Cartesian ones)."""
    from landscape.server.planning.motion.cartesian import tool_pose
    from landscape.server.planning.path_planning import PointSpec, load
    from landscape.server.planning.targets import Frame
    planner = Planner(Kinematics(ARM), DT)
    settings = MotionSettings(ARM)
    specs = [PointSpec(Q_HOME + [0.6 * np.sin(i / 2), 0.1 * np.cos(i / 3), 0.1 * np.sin(i / 4),
                                 0.0, 0.1 * np.sin(i / 2), 0.0], f"p{i}", i,
                       transition_speed=0.0 if i in (0, 39) else 40.0) for i in range(40)]
    path = load(planner, None, "line", Frame.JOINT, True, False, specs, settings, set(), Q_HOME)
    start = np.array(path.points[0].joints)
    run = list(plan_run_lazily(planner, path, start, settings, 1, long_section=0.3))
    assert len(run) > 5 and not run[0][1] and all(continues for _, continues in run[1:])
    assert [label for piece, _ in run for _, label in piece.marks] == list(range(40))
    q = np.concatenate([piece.positions for piece, _ in run])
    v = np.concatenate([piece.velocities for piece, _ in run])
    tip = tool_pose(planner.kinematics, path.tcp_matrix)
    excess = excess_per_sample(q, v, DT, planner.limits(settings, None), tip)
    assert excess.stretch() <= 1.0 + LIMIT_SLACK
    assert len(q) <= 1.005 * sum(len(p) for p in plan_run(planner, path, start, settings, 1))
