"""Single moves, stop / resume / abort, through gRPC on the simulated arm (lock-step clock).

Accuracy is measured on the recorder's per-cycle joint feedback (LLI recorder, MCAP), turned
into tool-tip positions with the forward kinematics.
"""
from __future__ import annotations

import math

import grpc
import numpy as np
import pytest

from landscape.server.device.states import State
from landscape.v1 import motion_pb2, settings_pb2, types_pb2

from support import Arm, distance_to_line, error_info, wait_until

JOINT, BASE = types_pb2.REFERENCE_FRAME_JOINT_FRAME, types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME
STRAIGHT = types_pb2.MOTION_TYPE_STRAIGHT_MOTION


@pytest.fixture
def arm(tmp_path, backend):
    a = Arm(tmp_path, backend=backend)
    yield a
    a.close()


def test_a_joint_move_reaches_its_goal_and_reports_started_then_done(arm):
    goal = [0.3, -0.2, 1.8, 0.1, 1.2, -0.4]
    reply = arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        point_name="p1", frame=JOINT, values=goal))
    assert reply.ret_val.ret_code == types_pb2.RETURN_CODE_CMD_STARTED_OK
    events = arm.wait_command(reply.ret_val.command_id)
    assert [e.event_id for e in events] == ["command_started", "command_done"]
    assert events[-1].command.point_name == "p1"
    wait_until(lambda: arm.server.device.state is State.RESTING)
    assert np.max(np.abs(arm.joints() - goal)) < 1e-3


def test_a_straight_move_keeps_the_tool_tip_on_the_line(arm):
    start = arm.tip()
    arm.record_start()
    reply = arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
        point_name="line", frame=BASE, values=[0.0, 0.5, 0.0, 0, 0, 0], motion_type=STRAIGHT,
        speed=100))
    assert arm.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"
    wait_until(lambda: np.linalg.norm(arm.server.device.feedback().velocity) < 1e-4)
    tips, _ = arm.recorded_tips()
    goal = start[:3, 3] + [0.0, 0.5, 0.0]
    deviation = distance_to_line(tips, start[:3, 3], goal).max()
    final = arm.tip()
    position_error = np.linalg.norm(final[:3, 3] - goal)
    angle_error = math.degrees(np.arccos(np.clip((np.trace(start[:3, :3].T @ final[:3, :3]) - 1) / 2,
                                                 -1, 1)))
    print(f"straight 0.5 m: max deviation {deviation * 1000:.3f} mm, final error "
          f"{position_error * 1000:.4f} mm, {angle_error:.5f} deg")
    assert deviation < 0.5e-3
    assert position_error < 0.1e-3 and angle_error < 0.01


def test_an_out_of_range_joint_target_is_refused_and_nothing_moves(arm):
    before = arm.joints().copy()
    with pytest.raises(grpc.RpcError) as refused:
        arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            frame=JOINT, values=[0, 0, 2.6, 0, 0, 0]))  # J3 is limited to 145 deg
    assert refused.value.code() is grpc.StatusCode.OUT_OF_RANGE
    assert error_info(refused.value).metadata["ret_code"] == "-3"
    assert arm.server.device.state is State.RESTING
    assert np.max(np.abs(arm.joints() - before)) < 1e-6


@pytest.mark.parametrize("values, code", [
    ([math.nan, 0, 0, 0, 0, 0], grpc.StatusCode.INVALID_ARGUMENT),
    ([0, 0, 0], grpc.StatusCode.INVALID_ARGUMENT),
    ([5.0, 0, 0, 0, 0, 0], grpc.StatusCode.OUT_OF_RANGE),       # 5 m away: unreachable
])
def test_bad_cartesian_targets_are_refused(arm, values, code):
    with pytest.raises(grpc.RpcError) as refused:
        arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(frame=BASE, values=values))
    assert refused.value.code() is code
    assert arm.server.device.state is State.RESTING


def test_stop_mid_line_holds_on_the_path_and_resume_reaches_the_end(tmp_path):
    arm = Arm(tmp_path, pace=2.0)
    try:
        start = arm.tip()
        goal = start[:3, 3] + [0.0, 0.5, 0.0]
        arm.record_start()
        reply = arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
            frame=BASE, values=[0.0, 0.5, 0.0, 0, 0, 0], motion_type=STRAIGHT, speed=20))
        wait_until(lambda: np.linalg.norm(arm.tip()[:3, 3] - start[:3, 3]) > 0.2, timeout=20)
        arm.device.StopMotion(motion_pb2.StopMotionRequest())
        assert arm.server.device.state is State.PAUSED
        state = arm.device.GetMotionControlState(settings_pb2.GetMotionControlStateRequest())
        assert state.motion_control_state == "robot_paused"
        held = arm.tip()[:3, 3]
        assert np.linalg.norm(arm.server.device.feedback().velocity) < 1e-3
        assert distance_to_line(held[None], start[:3, 3], goal)[0] < 0.5e-3

        arm.device.ResumeMotion(motion_pb2.ResumeMotionRequest())
        events = arm.wait_command(reply.ret_val.command_id)
        assert [e.event_id for e in events] == ["command_started", "command_paused",
                                                "command_resumed", "command_done"]
        tips, _ = arm.recorded_tips()
        assert distance_to_line(tips, start[:3, 3], goal).max() < 0.5e-3
        assert np.linalg.norm(arm.tip()[:3, 3] - goal) < 0.1e-3
    finally:
        arm.close()


def test_abort_after_stop_drops_the_motion(tmp_path):
    arm = Arm(tmp_path, pace=2.0)
    try:
        reply = arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            frame=JOINT, values=[1.5, 0, 1.5, 0, 1.5, 0], speed=10))
        wait_until(lambda: abs(arm.joints()[0]) > 0.2, timeout=20)
        arm.device.StopMotion(motion_pb2.StopMotionRequest())
        arm.device.AbortMotion(motion_pb2.AbortMotionRequest())
        assert arm.server.device.state is State.RESTING
        phases = [e.event_id for e in arm.wait_command(reply.ret_val.command_id,
                                                       ("command_aborted",))]
        assert phases[-1] == "command_aborted"
        state = arm.device.GetMotionControlState(settings_pb2.GetMotionControlStateRequest())
        assert state.motion_control_state == "robot_stopped_on_command"
        assert abs(arm.joints()[0] - 1.5) > 0.1  # it did not go on to the goal
    finally:
        arm.close()


def test_an_arc_keeps_its_radius_and_ends_at_the_goal(arm):
    start = arm.tip()
    p0 = start[:3, 3]
    # A half circle of radius 0.1 m in the horizontal plane, through p0 + (0.1, 0.1, 0) (with
    # 0.15 m the wrist, folded at the far end, comes within the collision margin of the
    # forearm: refused before it starts).
    via, goal = p0 + [0.1, 0.1, 0.0], p0 + [0.2, 0.0, 0.0]
    rpy = [math.pi, 0.0, math.pi]   # the start orientation: the tool points down
    arm.record_start()
    reply = arm.device.MoveArc(motion_pb2.MoveArcRequest(
        point_name="arc", frame=BASE, offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA,
        arc_value=[*via, *rpy], goal_value=[*goal, *rpy], speed=50))
    assert arm.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"
    tips, _ = arm.recorded_tips()
    centre = p0 + [0.1, 0.0, 0.0]
    radius_error = np.abs(np.linalg.norm(tips - centre, axis=1) - 0.1).max()
    final_error = np.linalg.norm(arm.tip()[:3, 3] - goal)
    print(f"arc r = 0.1 m: radius error {radius_error * 1000:.3f} mm, final {final_error * 1000:.4f} mm")
    assert radius_error < 0.5e-3 and final_error < 0.1e-3


WORLD, TOOL = (types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME,
               types_pb2.REFERENCE_FRAME_TOOL_FRAME)


def test_moves_in_the_world_and_tool_frames_land_where_the_frames_say(arm):
    arm.device.SetWorldCartesianFrame(settings_pb2.SetWorldCartesianFrameRequest(
        frame=types_pb2.Pose(x=0.5, y=-0.2, yaw=math.pi / 2)))
    arm.device.SetToolOffset(settings_pb2.SetToolOffsetRequest(offset=types_pb2.Pose(z=0.1)))
    tcp = arm.server.device.settings.tool_offset
    world = arm.server.device.settings.world_frame
    # Absolute in the world frame: the tool tip to world (0.2, 0.1, 0.6), pointing down.
    reply = arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        frame=WORLD, values=[0.2, 0.1, 0.6, math.pi, 0, 0], motion_type=STRAIGHT))
    assert arm.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"
    tip_world = np.linalg.inv(world) @ arm.tip() @ tcp
    assert np.allclose(tip_world[:3, 3], [0.2, 0.1, 0.6], atol=1e-4)
    assert np.allclose(tip_world[:3, 2], [0, 0, -1], atol=1e-4)
    # Relative in the tool frame: 5 cm along the tool's own z (down, here).
    before = arm.tip() @ tcp
    reply = arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
        frame=TOOL, values=[0, 0, 0.05, 0, 0, 0], motion_type=STRAIGHT))
    arm.wait_command(reply.ret_val.command_id)
    after = arm.tip() @ tcp
    assert np.allclose(after[:3, 3], before[:3, 3] + 0.05 * before[:3, 2], atol=1e-4)
    position = arm.device.GetRobotPosition(settings_pb2.GetRobotPositionRequest()).world_position
    assert (position.x, position.y, position.z) == pytest.approx((0.2, 0.1, 0.55), abs=1e-4)


def test_a_line_through_the_wrist_singularity_is_refused_before_anything_moves(arm):
    arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        frame=JOINT, values=[0, 0.2, 1.2, 0, 0.4, 0]))
    wait_until(lambda: arm.server.device.state is State.RESTING, timeout=10)
    wait_until(lambda: abs(arm.joints()[4] - 0.4) < 1e-4, timeout=10)
    before = arm.joints().copy()
    # Tilting the tool back through q5 = 0 while moving: the wrist flips on the way.
    with pytest.raises(grpc.RpcError) as refused:
        arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
            frame=BASE, values=[0, 0, 0, 0, -0.8, 0], motion_type=STRAIGHT))
    assert refused.value.code() is grpc.StatusCode.OUT_OF_RANGE
    info = error_info(refused.value)
    assert info.reason == "UNREACHABLE" and "fraction" in info.metadata
    assert np.max(np.abs(arm.joints() - before)) < 1e-6


def ruckig_stop(v: float, a0: float, a: float, j: float) -> float:
    """The distance of the time-optimal jerk-limited stop from speed v and acceleration a0
    (along v) within acceleration a and jerk j: ruckig's."""
    from ruckig import ControlInterface, InputParameter, Ruckig, Trajectory
    inp = InputParameter(1)
    inp.current_position, inp.current_velocity, inp.current_acceleration = [0.0], [v], [a0]
    inp.target_velocity, inp.target_acceleration = [0.0], [0.0]
    inp.max_velocity, inp.max_acceleration, inp.max_jerk = [10 * v], [a], [j]
    inp.control_interface = ControlInterface.Velocity
    trajectory = Trajectory(1)
    Ruckig(1).calculate(inp, trajectory)
    return trajectory.at_time(trajectory.duration)[0][0]


def test_stop_takes_no_longer_than_the_limits_need(tmp_path):
    arm = Arm(tmp_path, pace=1.0)   # real time: the stop lands long before the planned braking
    try:
        arm.record_start()
        arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            frame=JOINT, values=[3.0, 0, 1.5708, 0, 1.5708, 0], speed=60))
        wait_until(lambda: abs(arm.server.device.feedback().velocity[0]) > 2.0, timeout=20)
        arm.device.StopMotion(motion_pb2.StopMotionRequest())
        _, data = arm.recorded_tips()
        # The stop starts where the commanded speed of joint 1 peaks, and ends at rest.
        speed = np.abs(data["cmd_vel"][:, 0])
        start = int(np.argmax(speed))
        travelled = abs(data["cmd_pos"][-1, 0] - data["cmd_pos"][start, 0])
        # A stop brakes at the arm's full deceleration, whatever the set acceleration, and
        # ramps its deceleration within the jerk limit (issue 30): the shortest stop is
        # ruckig's time-optimal one from the peak speed, where the acceleration is zero
        # (before: v^2 / 2a).
        arm_model = arm.server.device.arm
        v, a, j = speed[start], arm_model.max_acceleration[0], arm_model.max_jerk[0]
        shortest = ruckig_stop(v, 0.0, a, j)
        decel = np.abs(np.diff(data["cmd_vel"][start:, 0])).max() / 0.004
        print(f"stop from {v:.2f} rad/s: {travelled:.4f} rad, shortest possible {shortest:.4f} rad"
              f", peak deceleration {decel:.2f} of {a:.2f} rad/s^2")
        assert travelled < 1.05 * shortest + v * 0.004   # within 5 % and a cycle
        assert decel <= a * (1 + 1e-6)
    finally:
        arm.close()
