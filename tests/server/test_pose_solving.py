"""Plan-only moves (DeviceService.SolvePose): the joints MoveAbsolute would move to, or the
refusal it would get, with nothing moving; real server, simulated arm on the lock-step clock."""
from __future__ import annotations

import math

import grpc
import numpy as np
import pytest

from landscape.robot.units import pose_matrix
from landscape.server.device.states import State
from landscape.v1 import (device_service_pb2_grpc, motion_pb2, pose_solving_pb2, settings_pb2,
                          types_pb2)

from support import error_info

JOINT, BASE, WORLD = (types_pb2.REFERENCE_FRAME_JOINT_FRAME,
                      types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME,
                      types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME)
DOWN = (math.pi, 0.0, 0.0)


def solve(device, frame, values, **fields):
    return device.SolvePose(pose_solving_pb2.SolvePoseRequest(frame=frame, values=values,
                                                              **fields), timeout=30)


def move(arm, frame, values, **fields):
    """MoveAbsolute, to its end; the refusal if refused."""
    reply = arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(frame=frame, values=values,
                                                                   **fields), timeout=30)
    assert arm.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"


def refused(call) -> grpc.RpcError:
    with pytest.raises(grpc.RpcError) as error:
        call()
    return error.value


def pose(p: types_pb2.Pose) -> np.ndarray:
    return np.array([p.x, p.y, p.z, p.roll, p.pitch, p.yaw])


def test_a_solved_pose_is_where_the_move_ends_and_nothing_moved(arm):
    goal = [0.6, 0.2, 0.6, *DOWN]
    watcher = device_service_pb2_grpc.DeviceServiceStub(grpc.insecure_channel(
        arm.server.target))                      # no session, no lock: a viewer
    before, sequence = arm.joints(), arm.server.bus.last_sequence
    # Joint motion last: its answer is compared with the move below (a straight line may end
    # with a wrist a turn away).
    for straight in (types_pb2.MOTION_TYPE_STRAIGHT_MOTION, types_pb2.MOTION_TYPE_JOINT_MOTION):
        answer = solve(watcher, BASE, goal, motion_type=straight)
        assert answer.reachable and not answer.HasField("refusal")
        tip = arm.kin.forward(np.array(answer.joints))
        assert np.allclose(tip[:3, 3], goal[:3], atol=1e-6)
        assert np.allclose(pose(answer.base_pose)[:3], goal[:3], atol=1e-6)
        assert answer.duration > 0
    assert arm.server.device.state is State.RESTING
    assert arm.server.bus.last_sequence == sequence       # no command, no event
    assert np.allclose(arm.joints(), before)

    move(arm, BASE, goal)
    assert np.allclose(arm.joints(), answer.joints, atol=1e-4)
    # From here, the same goal is no move at all; a world goal in degrees and millimetres.
    arm.device.SetUnits(settings_pb2.SetUnitsRequest(
        linear_units=types_pb2.LINEAR_UNIT_MILLIMETERS,
        angular_units=types_pb2.ANGULAR_UNIT_DEGREES), timeout=10)
    world = pose(solve(watcher, JOINT, np.degrees(answer.joints).tolist()).world_pose)
    again = solve(watcher, WORLD, world.tolist())
    assert again.reachable and again.units.angular == types_pb2.ANGULAR_UNIT_DEGREES
    assert np.allclose(again.joints, np.degrees(answer.joints), atol=1e-3)


def test_the_refusal_is_the_one_move_absolute_gets(arm):
    cases = {"beyond reach": (BASE, [5.0, 0.0, 0.6, *DOWN], {}),
             "beyond a joint's range": (JOINT, [0.0, 0.0, 9.0, 0.0, 0.0, 0.0], {}),
             "too fast": (BASE, [0.6, 0.2, 0.6, *DOWN], {"speed": 150.0})}
    for what, (frame, values, fields) in cases.items():
        answer = solve(arm.device, frame, values, **fields)
        assert not answer.reachable and len(answer.joints) == 0, what
        error = refused(lambda: move(arm, frame, values, **fields))
        info = error_info(error)
        assert (answer.refusal.status, answer.refusal.reason, answer.refusal.message) == (
            error.code().name, info.reason, error.details()), what
        assert dict(answer.refusal.metadata) == dict(info.metadata), what
    assert arm.server.device.state is State.RESTING


def test_a_goal_through_the_table_is_answered_with_the_collision(arm):
    near = arm.joints()
    over_a, _ = arm.kin.reverse(pose_matrix((0.6, -0.55, 0.45), DOWN), near)
    a, _ = arm.kin.reverse(pose_matrix((0.6, -0.55, 0.12), DOWN), over_a)
    over_b, _ = arm.kin.reverse(pose_matrix((0.6, 0.55, 0.45), DOWN), over_a)
    b, _ = arm.kin.reverse(pose_matrix((0.6, 0.55, 0.12), DOWN), over_b)
    for q in (over_a, a):
        move(arm, JOINT, list(q))
    answer = solve(arm.device, JOINT, list(b))
    assert not answer.reachable
    assert (answer.refusal.status, answer.refusal.reason) == ("FAILED_PRECONDITION", "COLLISION")
    assert answer.refusal.metadata["body_b"] == "table" and "table" in answer.refusal.message
    # Straight back up is clear.
    assert solve(arm.device, JOINT, list(over_a)).reachable


def test_a_malformed_goal_is_an_error_as_for_move_absolute(arm):
    for frame, values in ((BASE, [0.6, 0.2, 0.6]), (BASE, [0.6, math.nan, 0.6, *DOWN]),
                          (types_pb2.REFERENCE_FRAME_UNSPECIFIED, [0.0] * 6)):
        error = refused(lambda: solve(arm.device, frame, values))
        assert error.code() is grpc.StatusCode.INVALID_ARGUMENT, (values, error.details())
