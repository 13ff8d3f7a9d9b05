"""server/motion/cartesian.py: straight lines and arcs of the tool tip as dense joint paths, their
failures located along the segment, and their timing under tool speed limits."""
from __future__ import annotations

import math

import numpy as np
import pytest

from landscape.server.planning.motion.cartesian import (arc, circle, joint_waypoints, slerp, straight_line,
                                               straight_path, tool_pose)
from landscape.server.planning.motion.timing import LIMIT_SLACK, time_path
from landscape.server.planning.motion.trajectory import Limits, PlanningError
from landscape.robot.units import pose_matrix, rpy_matrix
from landscape.robot.arm import JERK_RAMP, arm_model
from landscape.robot.kinematics import Config, Kinematics, PosNeg, Shoulder

ARM = arm_model()
DT = 0.004
RIGHTY_UP = Config(Shoulder.RIGHTY, PosNeg.POSITIVE, PosNeg.POSITIVE)
TCP = pose_matrix([0.02, 0.0, 0.15], [0.0, 0.3, 0.0])     # a tool angled off the flange axis


@pytest.fixture(scope="module")
def kin() -> Kinematics:
    return Kinematics(ARM)


def joints_at(kin, xyz, rpy=(math.pi, 0.0, 0.0), config=RIGHTY_UP, tcp=None) -> np.ndarray:
    """Joints putting the tip (flange with tcp None) at a pose, in a configuration."""
    flange = pose_matrix(xyz, rpy) @ (np.eye(4) if tcp is None else np.linalg.inv(tcp))
    q, result = kin.reverse(flange, np.array([0.0, 0.3, 1.4, 0.0, 1.0, 0.0]), config)
    assert q is not None, result
    return q


def distance_to_line(points, a, b) -> np.ndarray:
    d = (b - a) / np.linalg.norm(b - a)
    rel = points - a
    return np.linalg.norm(rel - (rel @ d)[:, None] * d, axis=1)


def rotation_angle(Ra, Rb) -> np.ndarray:
    chord = np.linalg.norm(Ra - Rb, axis=(-2, -1))
    return 2.0 * np.arcsin(np.minimum(1.0, chord / (2.0 * math.sqrt(2.0))))


# ---- straight lines ------------------------------------------------------------------------------

@pytest.mark.parametrize("tcp", [None, TCP], ids=["flange", "tool-tip"])
def test_straight_line_stays_on_the_line_in_one_configuration(kin, tcp):
    q0 = joints_at(kin, [0.5, -0.25, 0.6], tcp=tcp)
    tip = tool_pose(kin, tcp)
    start = tip(q0)
    goal = start @ pose_matrix([0.0, 0.0, 0.0], [0.2, -0.1, 0.4])   # turn the tip too
    goal[:3, 3] = start[:3, 3] + [0.1, 0.48, 0.1]                     # 0.5 m
    Q = straight_line(kin, q0, goal, tcp=tcp)

    np.testing.assert_array_equal(Q[0], q0)
    poses = tip(Q)
    assert distance_to_line(poses[:, :3, 3], start[:3, 3], goal[:3, 3]).max() < 1e-6
    assert np.abs(poses[-1] - goal).max() < 1e-9
    steps = np.linalg.norm(np.diff(poses[:, :3, 3], axis=0), axis=1)
    assert steps.max() <= 0.005 + 1e-12 and np.ptp(steps) < 1e-9      # evenly spaced
    # Orientation: the shortest rotation, turned in proportion to the distance travelled.
    total = rotation_angle(start[:3, :3], goal[:3, :3])
    turned = rotation_angle(start[:3, :3], poses[:, :3, :3])
    f = np.linalg.norm(poses[:, :3, 3] - start[:3, 3], axis=1) / np.linalg.norm([0.1, 0.48, 0.1])
    np.testing.assert_allclose(turned, f * total, atol=1e-9)
    assert {kin.configuration(q) for q in Q} == {kin.configuration(q0)}
    assert np.abs(np.diff(Q, axis=0)).max() < 0.05                    # continuous


def test_the_wrist_turns_continuously_across_pi_and_stops_at_its_range(kin):
    q0 = joints_at(kin, [0.5, 0.0, 0.5])
    q0[5] = 3.0                                    # J6 near +pi: keep turning the same way
    start = kin.forward(q0)
    goal = start @ pose_matrix([0, 0, 0], [0, 0, 0.5])
    Q = straight_line(kin, q0, goal)
    assert Q[-1, 5] == pytest.approx(3.5)          # not 3.5 - 2 pi: no jump
    q0[5] = 4.5                                    # 270 deg is 4.712 rad: +0.5 leaves the range
    with pytest.raises(PlanningError) as err:
        straight_line(kin, q0, kin.forward(q0) @ pose_matrix([0, 0, 0], [0, 0, 0.5]))
    assert err.value.reason == "OUT_OF_JNT_RANGE"
    assert err.value.fraction == pytest.approx((4.712389 - 4.5) / 0.5, abs=0.05)


def test_a_line_out_of_the_workspace_fails_where_it_leaves(kin):
    q0 = joints_at(kin, [0.5, 0.0, 0.6])
    goal = kin.forward(q0)
    goal[:3, 3] += [1.0, 0.0, 0.0]                 # 1.5 m out: the reach is about 0.95 m
    with pytest.raises(PlanningError) as err:
        straight_line(kin, q0, goal)
    assert err.value.reason == "OUT_OF_WORKSPACE"
    assert 0.2 < err.value.fraction < 0.6


def test_a_line_through_the_wrist_singularity_fails(kin):
    q_plus = np.array([0.2, 0.3, 1.4, 0.1, 0.3, 0.2])
    q_minus = q_plus * [1, 1, 1, 1, -1, 1]         # the same arm, the wrist flexed the other way
    with pytest.raises(PlanningError) as err:
        straight_line(kin, q_plus, kin.forward(q_minus))
    assert err.value.reason == "SINGULARITY"
    assert 0.3 < err.value.fraction < 0.7


def test_a_line_needing_another_configuration_fails(kin):
    # Lefty (reaching backwards): J2 sits 0.05 m on the far side of J1, so the reach backwards
    # is shorter than righty's; going outwards the lefty arm runs out first.
    q0 = np.array([0.0, -0.3, -1.2, 0.0, 0.8, 0.0])
    assert kin.configuration(q0).shoulder == Shoulder.LEFTY
    goal = kin.forward(q0)
    goal[:3, 3] += [-0.25, 0.0, 0.0]
    with pytest.raises(PlanningError) as err:
        straight_line(kin, q0, goal)
    assert err.value.reason == "CONFIGURATION_CHANGE"
    assert 0.5 < err.value.fraction < 0.95
    # The goal is reachable, by the righty arm.
    assert kin.reverse(goal, q0, Config(Shoulder.RIGHTY, PosNeg.FREE, PosNeg.FREE))[0] is not None


def test_no_motion_is_one_sample(kin):
    q0 = joints_at(kin, [0.5, 0.0, 0.6])
    Q = straight_line(kin, q0, kin.forward(q0))
    assert Q.shape == (1, 6)


# ---- arcs ----------------------------------------------------------------------------------------

@pytest.mark.parametrize("tcp", [None, TCP], ids=["flange", "tool-tip"])
def test_arc_stays_on_the_circle(kin, tcp):
    q0 = joints_at(kin, [0.55, -0.2, 0.5], tcp=tcp)
    tip = tool_pose(kin, tcp)
    start = tip(q0)
    via, goal = start.copy(), start @ pose_matrix([0, 0, 0], [0.0, 0.0, 1.0])
    via[:3, 3] += [0.15, 0.15, 0.05]
    goal[:3, 3] = start[:3, 3] + [0.0, 0.35, 0.1]
    Q = arc(kin, q0, via, goal, tcp=tcp)
    centre, radius, *_ = circle(start[:3, 3], via[:3, 3], goal[:3, 3])
    poses = tip(Q)
    assert np.abs(np.linalg.norm(poses[:, :3, 3] - centre, axis=1) - radius).max() < 1e-6
    assert np.abs(poses[-1] - goal).max() < 1e-9
    # It passes through via (between two samples at most a step apart).
    assert np.linalg.norm(poses[:, :3, 3] - via[:3, 3], axis=1).min() < 0.005
    # In the plane of the three points.
    normal = np.cross(via[:3, 3] - start[:3, 3], goal[:3, 3] - start[:3, 3])
    assert np.abs((poses[:, :3, 3] - centre) @ normal / np.linalg.norm(normal)).max() < 1e-9


def test_collinear_arc_points_are_degenerate(kin):
    q0 = joints_at(kin, [0.5, 0.0, 0.6])
    start = kin.forward(q0)
    via, goal = start.copy(), start.copy()
    via[:3, 3] += [0.0, 0.1, 0.0]
    goal[:3, 3] += [0.0, 0.3, 0.0]
    with pytest.raises(PlanningError) as err:
        arc(kin, q0, via, goal)
    assert err.value.reason == "DEGENERATE"


def test_circle_orders_the_points():
    p0, p1, p2 = np.array([1.0, 0, 0]), np.array([0, 1.0, 0]), np.array([-1.0, 0, 0])
    centre, radius, u, w, sweep = circle(p0, p1, p2)
    np.testing.assert_allclose(centre, 0, atol=1e-15)
    assert radius == pytest.approx(1.0) and sweep == pytest.approx(math.pi)
    # Three quarters of a turn when the via point comes first on the long way round.
    _, _, _, _, sweep = circle(p0, np.array([0, -1.0, 0]), np.array([0, 1.0, 0]))
    assert sweep == pytest.approx(1.5 * math.pi)


def test_slerp_is_the_shortest_rotation():
    R0, R1 = rpy_matrix(0.1, 0.2, 0.3), rpy_matrix(2.0, -0.5, 2.9)
    f = np.linspace(0, 1, 11)
    R = slerp(R0, R1, f)
    np.testing.assert_allclose(R[0], R0, atol=1e-12)
    np.testing.assert_allclose(R[-1], R1, atol=1e-12)
    steps = rotation_angle(R[:-1], R[1:])
    np.testing.assert_allclose(steps, steps[0], atol=1e-12)         # constant angular rate
    assert rotation_angle(R0, R1) <= math.pi
    # Half a turn exactly: still a rotation, and the right one at the end.
    R2 = R0 @ rpy_matrix(math.pi, 0, 0)
    R = slerp(R0, R2, f)
    np.testing.assert_allclose(R[-1], R2, atol=1e-9)
    np.testing.assert_allclose(np.linalg.det(R), 1.0, atol=1e-12)


# ---- paths of several poses ----------------------------------------------------------------------

def test_straight_path_marks_its_goals_and_locates_failures(kin):
    q0 = joints_at(kin, [0.5, -0.2, 0.6])
    start = kin.forward(q0)
    goals = np.array([start, start, start])
    goals[0, :3, 3] += [0.0, 0.2, 0.0]
    goals[1, :3, 3] += [0.1, 0.2, 0.0]
    goals[2, :3, 3] += [0.1, 0.0, 0.0]
    Q, rows = straight_path(kin, q0, goals)
    assert len(rows) == 3 and rows[-1] == len(Q) - 1
    np.testing.assert_allclose(kin.forward(Q[list(rows)]), goals, atol=1e-9)
    goals[1, :3, 3] += [1.5, 0.0, 0.0]
    with pytest.raises(PlanningError) as err:
        straight_path(kin, q0, goals)
    assert err.value.index == 1 and err.value.fraction is not None
    assert err.value.reason == "OUT_OF_WORKSPACE"


def test_joint_waypoints_report_the_unreachable_index(kin):
    q0 = joints_at(kin, [0.5, -0.2, 0.6])
    poses = kin.forward(np.array([q0, q0 + 0.2, q0 - 0.2]))
    Q = joint_waypoints(kin, poses, q0)
    np.testing.assert_allclose(kin.forward(Q), poses, atol=1e-9)
    poses[2, :3, 3] = [2.0, 0.0, 0.5]
    with pytest.raises(PlanningError) as err:
        joint_waypoints(kin, poses, q0)
    assert err.value.reason == "OUT_OF_WORKSPACE" and err.value.index == 2


# ---- timing Cartesian paths ----------------------------------------------------------------------

@pytest.mark.parametrize("tcp", [None, TCP], ids=["flange", "tool-tip"])
def test_timed_line_keeps_the_linear_speed_limit_and_reaches_it(kin, tcp):
    q0 = joints_at(kin, [0.5, -0.25, 0.6], tcp=tcp)
    tip = tool_pose(kin, tcp)
    start = tip(q0)
    goal = start.copy()
    goal[:3, 3] += [0.0, 0.5, 0.0]
    limits = Limits.scaled(ARM, 100, 100, linear_velocity=0.25)
    tr = time_path(straight_line(kin, q0, goal, tcp=tcp), limits, DT, tool_path=tip)

    p = tip(tr.positions)[:, :3, 3]
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / DT
    assert speed.max() <= 0.25 * (1 + LIMIT_SLACK)
    assert speed.max() >= 0.99 * 0.25
    assert tr.duration == pytest.approx(0.5 / 0.25, rel=0.05)
    assert np.abs(tr.velocities).max(axis=0).max() <= np.max(limits.velocity)
    # Between the IK samples the joint spline leaves the line by micrometres only.
    assert distance_to_line(p, start[:3, 3], goal[:3, 3]).max() < 2e-5
    np.testing.assert_allclose(p[-1], goal[:3, 3], atol=1e-9)


def test_timed_reorientation_keeps_the_angular_speed_limit(kin):
    q0 = joints_at(kin, [0.5, 0.0, 0.5], tcp=TCP)
    tip = tool_pose(kin, TCP)
    start = tip(q0)
    goal = start @ pose_matrix([0, 0, 0], [0.0, 0.0, 1.2])        # turn about the tip only
    limits = Limits.scaled(ARM, 100, 100, angular_velocity=0.5)
    tr = time_path(straight_line(kin, q0, goal, tcp=TCP), limits, DT, tool_path=tip)
    R = tip(tr.positions)[:, :3, :3]
    rate = rotation_angle(R[:-1], R[1:]) / DT
    assert rate.max() <= 0.5 * (1 + LIMIT_SLACK) and rate.max() >= 0.99 * 0.5
    assert np.linalg.norm(tip(tr.positions)[:, :3, 3] - start[:3, 3], axis=1).max() < 1e-5


def tip_accelerations(tip, positions) -> tuple[np.ndarray, np.ndarray]:
    """Per-cycle linear (m/s^2) and angular (rad/s^2) tip accelerations of sampled joints, held
    at rest before and after: second differences of positions, differences of rotation steps."""
    poses = tip(np.concatenate([positions[:1], positions, positions[-1:]]))
    p = poses[:, :3, 3]
    linear = np.linalg.norm(p[2:] - 2 * p[1:-1] + p[:-2], axis=1) / DT**2
    R = poses[:, :3, :3]
    steps = []
    for Ra, Rb in zip(R[:-1], R[1:]):
        M = Rb @ Ra.T
        angle = rotation_angle(Ra, Rb)
        axis = np.array([M[2, 1] - M[1, 2], M[0, 2] - M[2, 0], M[1, 0] - M[0, 1]])
        n = np.linalg.norm(axis)
        steps.append(axis * (angle / n) if n > 0 else np.zeros(3))
    angular = np.linalg.norm(np.diff(steps, axis=0), axis=1) / DT**2
    return linear, angular


@pytest.mark.parametrize("tcp", [None, TCP], ids=["flange", "tool-tip"])
def test_timed_line_keeps_the_linear_acceleration_limit_and_reaches_it(kin, tcp):
    q0 = joints_at(kin, [0.5, -0.25, 0.6], tcp=tcp)
    tip = tool_pose(kin, tcp)
    goal = tip(q0)
    goal[:3, 3] += [0.0, 0.5, 0.0]
    limits = Limits.scaled(ARM, 100, 100, linear_velocity=1.0, linear_acceleration=0.8)
    tr = time_path(straight_line(kin, q0, goal, tcp=tcp), limits, DT, tool_path=tip)
    linear, _ = tip_accelerations(tip, tr.positions)
    assert linear.max() <= 0.8 * (1 + 1e-6)
    assert linear.max() >= 0.98 * 0.8
    # Triangle profile on 0.5 m at 0.8 m/s^2 (never reaches 1 m/s): 2 sqrt(d / a), and
    # the jerk limit's ramps (issue 30): about one ramp more.
    assert tr.duration == pytest.approx(2 * math.sqrt(0.5 / 0.8) + JERK_RAMP, rel=0.01)


def test_timed_reorientation_keeps_the_angular_acceleration_limit(kin):
    q0 = joints_at(kin, [0.5, 0.0, 0.5], tcp=TCP)
    tip = tool_pose(kin, TCP)
    goal = tip(q0) @ pose_matrix([0, 0, 0], [0.0, 0.0, 1.2])
    limits = Limits.scaled(ARM, 100, 100, angular_acceleration=2.0)
    tr = time_path(straight_line(kin, q0, goal, tcp=TCP), limits, DT, tool_path=tip)
    _, angular = tip_accelerations(tip, tr.positions)
    assert 0.98 * 2.0 <= angular.max() <= 2.0 * (1 + 1e-6)
    assert tr.duration == pytest.approx(2 * math.sqrt(1.2 / 2.0) + JERK_RAMP, rel=0.01)


def test_timed_arc_keeps_the_linear_acceleration_limit_with_its_centripetal_part(kin):
    q0 = joints_at(kin, [0.55, -0.15, 0.6])
    tip = tool_pose(kin)
    p0 = tip(q0)[:3, 3]
    via, goal = tip(q0), tip(q0)
    via[:3, 3] = p0 + [0.15, 0.15, 0.0]
    goal[:3, 3] = p0 + [0.30, 0.0, 0.0]
    limits = Limits.scaled(ARM, 100, 100, linear_acceleration=1.5)
    tr = time_path(arc(kin, q0, via, goal), limits, DT, tool_path=tip)
    linear, _ = tip_accelerations(tip, tr.positions)
    assert 0.97 * 1.5 <= linear.max() <= 1.5 * (1 + 1e-6)
    # On the half circle of radius 0.15 m the centripetal part alone caps the speed at
    # sqrt(a r) = 0.47 m/s: the duration is at least the length over that speed.
    assert tr.duration >= math.pi * 0.15 / math.sqrt(1.5 * 0.15)
