"""server/motion/timing.py: TOPP-RA timing of joint paths, checked on the sampled trajectory.

Every trajectory is checked where the cycle sees it: at each 4 ms sample, velocities and the
forward-difference accelerations of Trajectory.accelerations() within the limits (relative
slack LIMIT_SLACK = 1e-9: the planner re-times until the samples hold, it does not round).
The optimality of TOPP-RA itself is checked on jerk-free limits (`jerk_free`); the
jerk-limited timing the server uses (issue 30), and every kind of motion, in
test_motion_kinds.py.
"""
from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from landscape.server.planning.motion.timing import (LIMIT_SLACK, ConstAccelProfile, chord_parameters,
                                            gridpoints, speed_caps, time_path, topp_ra,
                                            toppra_reference)
from landscape.server.planning.motion.trajectory import JointPath, Limits, PlanningError, Trajectory
from landscape.robot.arm import arm_model
from support import random_walk

ARM = arm_model()
DT = 0.004
Q_HOME = np.array([0.0, 0.3, 1.4, 0.0, 0.9, 0.0])


def jerk_free(limits: Limits) -> Limits:
    """The same limits without a jerk limit: TOPP-RA's own, bang-bang timing."""
    return dataclasses.replace(limits, jerk=None)


def assert_within_limits(tr: Trajectory, limits: Limits) -> None:
    v = np.abs(tr.velocities) / limits.velocity
    a = np.abs(tr.accelerations()) / limits.acceleration
    assert v.max() <= 1.0 + LIMIT_SLACK, f"velocity at {v.max():.6f} of its limit"
    assert a.max() <= 1.0 + LIMIT_SLACK, f"acceleration at {a.max():.6f} of its limit"
    assert np.all(tr.positions >= ARM.lower - 1e-9) and np.all(tr.positions <= ARM.upper + 1e-9)


def trapezoid_time(distance: float, v: float, a: float) -> float:
    """Time-optimal rest-to-rest time over `distance` with speed v and acceleration a limits."""
    if distance * a > v * v:
        return distance / v + v / a            # trapezoid: cruise at v
    return 2.0 * math.sqrt(distance / a)       # triangle: never reaches v


def walk(n: int, seed: int, step: float = 0.4) -> np.ndarray:
    return random_walk(ARM, Q_HOME, n, seed, step)


# ---- joint moves ---------------------------------------------------------------------------------

@pytest.mark.parametrize("joint, distance, speed, accel", [
    (0, 3.0, 100, 100),      # trapezoid
    (0, 0.5, 100, 100),      # triangle
    (2, -1.2, 50, 30),       # scaled limits
    (5, 4.0, 100, 100),      # the fast wrist
])
def test_single_joint_move_is_the_analytic_time_optimal_profile(joint, distance, speed, accel):
    limits = jerk_free(Limits.scaled(ARM, speed, accel))
    goal = Q_HOME.copy()
    goal[joint] += distance
    tr = time_path([Q_HOME, goal], limits, DT)

    np.testing.assert_array_equal(tr.positions[0], Q_HOME)
    np.testing.assert_array_equal(tr.positions[-1], goal)
    assert not tr.velocities[0].any() and not tr.velocities[-1].any()
    assert_within_limits(tr, limits)
    others = np.delete(np.arange(6), joint)
    assert np.abs(tr.positions[:, others] - Q_HOME[others]).max() < 1e-12
    best = trapezoid_time(abs(distance), limits.velocity[joint], limits.acceleration[joint])
    # Never faster than the optimum; slower by the TOPP-RA grid and the last partial cycle.
    assert best - 1e-9 <= tr.duration <= 1.01 * best + DT, (tr.duration, best)
    assert tr.marks == ((0, 0), (len(tr) - 1, 1))
    assert tr.duration == pytest.approx((len(tr) - 1) * DT)


def test_multi_joint_straight_move_is_the_slowest_joints_profile():
    """On a straight joint line q0 + d * sigma(t), joint j bounds sigma' by v_j / |d_j| and
    sigma'' by a_j / |d_j|: the optimum is the trapezoid of sigma under the tightest bounds."""
    limits = jerk_free(Limits.scaled(ARM, 80, 60))
    goal = Q_HOME + np.array([1.0, -0.4, 0.7, 2.0, -1.1, 3.0])
    tr = time_path([Q_HOME, goal], limits, DT)
    d = np.abs(goal - Q_HOME)
    best = trapezoid_time(1.0, np.min(limits.velocity / d), np.min(limits.acceleration / d))
    assert best - 1e-9 <= tr.duration <= 1.01 * best + DT
    assert_within_limits(tr, limits)
    # Every sample on the line.
    sigma = (tr.positions - Q_HOME) / (goal - Q_HOME)
    assert np.ptp(sigma, axis=1).max() < 1e-9


def test_a_zero_length_move_is_one_sample_at_rest():
    tr = time_path([Q_HOME, Q_HOME], Limits.scaled(ARM, 100, 100), DT)
    assert len(tr) == 1 and tr.duration == 0.0 and not tr.velocities.any()
    assert tr.marks == ((0, 0), (0, 1))


# ---- paths through waypoints ---------------------------------------------------------------------

def test_blended_path_passes_every_waypoint_without_stopping():
    W = walk(8, seed=3)
    limits = Limits.scaled(ARM, 100, 100)
    tr = time_path(W, limits, DT)
    assert_within_limits(tr, limits)
    samples = [k for k, _ in tr.marks]
    assert [i for _, i in tr.marks] == list(range(len(W)))
    assert samples == sorted(samples) and samples[0] == 0 and samples[-1] == len(tr) - 1
    speed = np.linalg.norm(tr.velocities, axis=1)
    for k, i in tr.marks:
        # The mark is the sample nearest the waypoint: within half a cycle of travel.
        assert np.linalg.norm(tr.positions[k] - W[i]) <= speed.max() * DT / 2 + 1e-9
        if 0 < i < len(W) - 1:
            assert speed[k] > 0.05 * speed.max(), f"waypoint {i}: speed {speed[k]:.3g} rad/s"
    # Between the ends the arm never rests.
    assert speed[1:-1].min() > 0.0


def test_a_stop_in_the_middle_comes_to_rest_there():
    W = walk(6, seed=4)
    limits = Limits.scaled(ARM, 100, 100)
    tr = time_path(W, limits, DT, stops=[False, False, True, False, False, False])
    assert_within_limits(tr, limits)
    k = dict((i, k) for k, i in tr.marks)[2]
    np.testing.assert_array_equal(tr.positions[k], W[2])
    assert not tr.velocities[k].any()
    # The other intermediate waypoints are passed moving.
    speed = np.linalg.norm(tr.velocities, axis=1)
    assert all(speed[dict((i, k) for k, i in tr.marks)[i]] > 0 for i in (1, 3, 4))


def test_repeated_waypoints_are_one_point():
    W = walk(4, seed=5)
    W = np.insert(W, 2, W[1], axis=0)                    # waypoint 2 repeats waypoint 1
    tr = time_path(W, Limits.scaled(ARM, 100, 100), DT)
    marks = dict((i, k) for k, i in tr.marks)
    assert marks[1] == marks[2] and len(tr.marks) == 5


def test_a_waypoint_out_of_range_reports_its_index():
    W = walk(5, seed=6)
    W[3, 1] = ARM.upper[1] + 0.1
    with pytest.raises(PlanningError) as err:
        time_path(W, Limits.scaled(ARM, 100, 100), DT)
    assert err.value.reason == "OUT_OF_JNT_RANGE" and err.value.index == 3


def test_a_spline_swinging_out_of_range_reports_the_piece():
    # J3 back and forth near its upper limit: the spline overshoots between waypoints 1 and 2.
    top = ARM.upper[2]
    W = np.tile(Q_HOME, (4, 1))
    W[:, 2] = [0.0, top - 0.01, top - 0.01, 0.0]
    W[:, 0] = [0.0, 0.0, 1.5, 1.5]
    with pytest.raises(PlanningError) as err:
        time_path(W, Limits.scaled(ARM, 100, 100), DT)
    assert err.value.reason == "OUT_OF_JNT_RANGE" and err.value.index == 1


# ---- the solver ----------------------------------------------------------------------------------

def test_the_stage_solver_returns_what_toppra_returns_on_the_same_grid():
    """Our closed-form stages against toppra's seidel LP solver, same path, grid, constraints."""
    pytest.importorskip("toppra")
    W = walk(12, seed=7)
    limits = Limits.scaled(ARM, 70, 50)
    s, keep = chord_parameters(W)
    path = JointPath(s, W[keep])
    grid, _ = gridpoints(path)
    ours = topp_ra(path, grid, limits.acceleration, speed_caps(path, grid, limits))
    theirs = toppra_reference(path, grid, limits)
    scale = ours.max()
    assert np.abs(ours - theirs).max() < 1e-6 * scale
    assert ConstAccelProfile(grid, ours).duration == pytest.approx(
        ConstAccelProfile(grid, theirs).duration, rel=1e-6)


def test_the_stage_solver_takes_an_acceleration_limit_per_stage():
    """What the jerk-limited timing lowers where its samples exceed a limit (issue 30): one
    row of accelerations per stage. The same row everywhere is the (6,) limit; a stretch
    with half the limit keeps half, there only."""
    W = walk(8, seed=4)
    limits = Limits.scaled(ARM, 100, 100)
    s, keep = chord_parameters(W)
    path = JointPath(s, W[keep])
    grid, _ = gridpoints(path)
    caps = speed_caps(path, grid, limits)
    whole = topp_ra(path, grid, limits.acceleration, caps)
    rows = np.tile(limits.acceleration, (len(grid) - 1, 1))
    assert np.array_equal(topp_ra(path, grid, rows, caps), whole)
    stretch = (grid[:-1] > 0.3 * s[-1]) & (grid[:-1] < 0.6 * s[-1])
    rows[stretch] *= 0.5
    xs = topp_ra(path, grid, rows, caps)
    u = np.diff(xs) / (2.0 * np.diff(grid))
    q1, q2 = path.evaluate(grid, (1, 2))
    at_start = np.abs(q1[:-1] * u[:, None] + q2[:-1] * xs[:-1, None])
    assert (at_start / rows).max() <= 1 + 1e-9
    assert (at_start[stretch] / limits.acceleration).max() <= 0.5 + 1e-9
    assert (at_start[~stretch] / limits.acceleration).max() > 0.99     # full elsewhere
    assert ConstAccelProfile(grid, xs).duration > ConstAccelProfile(grid, whole).duration


def test_finer_grids_converge_from_above():
    """TOPP-RA's interpolation scheme is conservative: the duration falls towards the optimum
    as the grid refines; the default grid is within 1% of a 10x finer one."""
    W = walk(12, seed=8)
    limits = Limits.scaled(ARM, 100, 100)
    s, keep = chord_parameters(W)
    path = JointPath(s, W[keep])

    def duration(**grid_options):
        grid, _ = gridpoints(path, **grid_options)
        caps = speed_caps(path, grid, limits)
        return ConstAccelProfile(grid, topp_ra(path, grid, limits.acceleration, caps)).duration

    default, fine = duration(), duration(chord_tol=2e-6, max_step=0.005, min_points=1000)
    assert fine <= default <= 1.01 * fine


def test_joint_path_is_a_natural_c2_spline_through_the_waypoints():
    W = walk(7, seed=9)
    s, _ = chord_parameters(W)
    path = JointPath(s, W)
    np.testing.assert_allclose(path(s), W, atol=1e-12)
    eps = 1e-7
    for order in (0, 1, 2):                      # continuous at the inner knots
        left, right = path(s[1:-1] - eps, order), path(s[1:-1] + eps, order)
        assert np.abs(left - right).max() < 1e-4
    np.testing.assert_allclose(path(s[[0, -1]], 2), 0.0, atol=1e-12)   # natural ends
    # Derivatives agree with finite differences.
    x = np.linspace(s[0] + 0.01, s[-1] - 0.01, 50)
    np.testing.assert_allclose(path(x, 1), (path(x + eps) - path(x - eps)) / (2 * eps), atol=1e-6)


# ---- records -------------------------------------------------------------------------------------

def test_limits_scaled():
    limits = Limits.scaled(ARM, 50, 25)
    np.testing.assert_allclose(limits.velocity, 0.5 * np.array(ARM.max_velocity))
    np.testing.assert_allclose(limits.acceleration, 0.25 * np.array(ARM.max_acceleration))
    assert limits.linear_velocity == pytest.approx(0.5 * ARM.max_linear_velocity)
    assert Limits.scaled(ARM, 50, 25, linear_velocity=0.1).linear_velocity == 0.1
    # An absolute Cartesian limit is a cap of its own, not scaled; the percent still holds.
    capped = Limits.scaled(ARM, 50, 25, linear_velocity=99.0)
    assert capped.linear_velocity == 0.5 * ARM.max_linear_velocity
    assert Limits.scaled(ARM, 60, 25, linear_velocity=0.2).linear_velocity == 0.2
    assert Limits.scaled(ARM, 50, 25).linear_acceleration == 0.25 * ARM.max_linear_acceleration
    both = Limits.scaled(ARM, 50, 40, angular_velocity=0.3, linear_acceleration=0.5,
                         angular_acceleration=0.7)
    assert (both.angular_velocity, both.linear_acceleration, both.angular_acceleration) == (
        0.3, 0.5, 0.7)
    for bad in (0, -5, 101, math.nan):
        with pytest.raises(ValueError):
            Limits.scaled(ARM, bad, 50)


def test_bad_input():
    limits = Limits.scaled(ARM, 100, 100)
    with pytest.raises(ValueError):
        time_path(np.zeros((3, 5)), limits, DT)
    with pytest.raises(ValueError):
        time_path([Q_HOME, Q_HOME + 1], limits, 0.0)
    with pytest.raises(ValueError):
        time_path([Q_HOME, Q_HOME + 1], limits, DT, stops=[True])
    with pytest.raises(ValueError):
        time_path([Q_HOME, Q_HOME + np.nan], limits, DT)


def test_planning_error_carries_reason_and_place():
    err = PlanningError("SINGULARITY", "wrist", fraction=0.25)
    assert err.reason == "SINGULARITY" and err.fraction == 0.25 and err.index is None
    moved = err.at_index(3)
    assert moved.index == 3 and moved.fraction == 0.25 and moved.reason == "SINGULARITY"
    assert isinstance(err, ValueError)
    with pytest.raises(ValueError):
        PlanningError("NOT_A_REASON")


def test_the_stage_solver_with_tool_acceleration_rows_returns_what_toppra_returns():
    """The one-sided rows of the tool's acceleration (an arc: tangential and centripetal
    faces), ours against toppra's on the same grid."""
    pytest.importorskip("toppra")
    from landscape.server.planning.motion.cartesian import arc, tool_pose
    from landscape.server.planning.motion.timing import tool_constraints
    from landscape.robot.kinematics import Kinematics
    kin = Kinematics(ARM)
    q0 = np.array([0.0, 0.3, 1.4, 0.0, 1.4, 0.0])
    tip = tool_pose(kin)
    p0 = tip(q0)
    via, goal = p0.copy(), p0.copy()
    via[:3, 3] += [0.1, 0.1, 0.0]
    goal[:3, 3] += [0.2, 0.0, 0.0]
    W = arc(kin, q0, via, goal)
    limits = Limits.scaled(ARM, 100, 100, linear_acceleration=1.0, angular_acceleration=3.0)
    s, keep = chord_parameters(W)
    path = JointPath(s, W[keep])
    grid, _ = gridpoints(path)
    caps, rows = tool_constraints(path, grid, limits, tip)
    assert rows is not None and rows[0].shape[1] > 4      # the curved faces are in
    ours = topp_ra(path, grid, limits.acceleration, caps, rows)
    theirs = toppra_reference(path, grid, limits, tip)
    assert np.abs(ours - theirs).max() < 1e-6 * ours.max()


@pytest.mark.parametrize("fraction", [0.02, 0.1, 0.25, 0.4])
def test_a_waypoint_is_passed_at_its_pass_speed(fraction):
    """The fastest joint, against its maximum velocity, at the waypoint's mark."""
    W = np.array([Q_HOME, Q_HOME + [1.0, 0.2, -0.3, 0.5, 0.2, 0.4],
                  Q_HOME + [2.0, 0.5, 0.0, 0.0, 0.5, 0.9]])
    limits = Limits.scaled(ARM, 80, 100)
    tr = time_path(W, limits, DT, pass_speeds={1: fraction})
    assert_within_limits(tr, limits)
    sample = dict((i, k) for k, i in tr.marks)[1]
    # At the waypoint's sample and the cycles either side: the speed holds for a moment. (The
    # jerk-limited timing may slow a whole section down by a few % where its samples exceed a
    # limit elsewhere: issue 30.)
    for k in (sample - 1, sample, sample + 1):
        speed = np.max(np.abs(tr.velocities[k]) / np.array(ARM.max_velocity))
        assert speed == pytest.approx(fraction, rel=0.025), k - sample
    free = time_path(W, limits, DT)
    assert tr.duration >= free.duration
