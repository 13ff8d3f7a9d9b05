"""Tiny positive rates and huge dwells are refused before planning (OUT_OF_RANGE naming the
field and its bound) instead of planning motions of years; a 10-minute motion stays possible.
Real server on the lock-step clock; each refusal changes nothing and returns at once."""
from __future__ import annotations

import time

import grpc
import numpy as np
import pytest

from landscape.server.planning.moves import Planner
from landscape.server.device.motion_settings import MAX_MOTION_SECONDS, MotionSettings
from landscape.server.device.states import State
from landscape.server.planning.targets import Frame
from landscape.robot.arm import arm_model
from landscape.robot.kinematics import Kinematics
from landscape.v1 import motion_pb2, settings_pb2, types_pb2

from support import error_info

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
ABSOLUTE = types_pb2.OFFSET_TYPE_ABSOLUTE_DATA


def assert_refused(arm, call, field: str, bound: str) -> None:
    """OUT_OF_RANGE naming `field` and a bound (metadata key `bound`), nothing moved, the
    device still resting; refused before planning: a refusal that waited on planning took 30 s
    and more, so it would end past the calls' 10 s deadline, DEADLINE_EXCEEDED."""
    before = arm.joints().copy()
    with pytest.raises(grpc.RpcError) as refused:
        call()
    error = refused.value
    assert error.code() is grpc.StatusCode.OUT_OF_RANGE, error.details()
    info = error_info(error)
    assert info.metadata["field"] == field, dict(info.metadata)
    assert bound in info.metadata, dict(info.metadata)
    assert arm.server.device.state is State.RESTING
    assert np.max(np.abs(arm.joints() - before)) < 1e-6


def test_a_move_at_speed_5e_324_is_refused(arm):
    assert_refused(arm, lambda: arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
        frame=JOINT, values=[0.1, 0, 0, 0, 0, 0], speed=5e-324), timeout=10), "speed", "minimum")


@pytest.mark.parametrize("speed", [1e-9, 1e-6])
def test_a_tenth_of_a_radian_at_a_tiny_speed_is_refused(arm, speed):
    goal = arm.joints() + [0.1, 0, 0, 0, 0, 0]
    assert_refused(arm, lambda: arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        frame=JOINT, values=goal, speed=speed), timeout=10), "speed", "minimum")


def test_a_tiny_percent_acceleration_is_refused_and_the_next_move_works(arm):
    before = arm.server.device.settings.accel_percent
    assert_refused(arm, lambda: arm.device.SetAcceleration(settings_pb2.SetAccelerationRequest(
        accel=1e-310, attribute=types_pb2.ACCEL_TYPE_PERCENT_ACCEL), timeout=10),
        "percent_accel", "minimum")
    assert arm.server.device.settings.accel_percent == before
    reply = arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
        frame=JOINT, values=[0.05, 0, 0, 0, 0, 0]))
    assert arm.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"


def test_a_legal_speed_that_would_take_hours_is_refused_before_planning(arm):
    arm.device.SetSpeed(settings_pb2.SetSpeedRequest(
        speed=0.01, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED))   # the least allowed
    assert_refused(arm, lambda: arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
        frame=JOINT, values=[2.0, 0, 0, 0, 0, 0]), timeout=10), "speed", "maximum")


def path_header(name: str, n: int):
    return motion_pb2.PathHeader(path_name=name, frame=JOINT, offset_type=ABSOLUTE,
                                 motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                 number_of_points=n)


def test_a_path_point_with_a_dwell_of_1e9_s_is_refused_at_load(arm):
    q = arm.joints()
    tag = types_pb2.TagStruct(joint_values=q + [0.1, 0, 0, 0, 0, 0], time_delay=1e9)
    assert_refused(arm, lambda: arm.device.PathLoad(iter([motion_pb2.PathLoadRequest(
        header=path_header("long", 1), tags=[tag])]), timeout=10), "time_delay", "maximum")
    assert arm.server.device.path_runs.paths.get("long") is None


def test_dwells_adding_up_past_the_bound_refuse_the_path(arm):
    """Each dwell within the bound, their sum past it: the pass is refused before it is
    planned -- at load, where the whole path is planned for its collision check."""
    q = arm.joints()
    tags = [types_pb2.TagStruct(joint_values=q + [0.1 * i, 0, 0, 0, 0, 0],
                                time_delay=0.75 * MAX_MOTION_SECONDS) for i in range(2)]
    assert_refused(arm, lambda: arm.device.PathLoad(iter([motion_pb2.PathLoadRequest(
        header=path_header("dwells", 2), tags=tags)]), timeout=10), "time_delay", "maximum")
    assert arm.server.device.path_runs.paths.get("dwells") is None


def test_a_ten_minute_motion_is_planned():
    """The bound leaves room for long motions: a joint move of 600 s plans, sample by sample."""
    arm = arm_model()
    planner = Planner(Kinematics(arm), 0.004)
    q0 = np.array([-2.0, 0.0, 1.5, 0.0, 1.0, 0.0])
    settings = MotionSettings(arm).with_speed_percent(
        100.0 * 4.0 / 600.0 / arm.max_velocity[0])          # 4 rad of joint 1 in ~600 s
    start = time.perf_counter()
    trajectory = planner.move(q0, settings, Frame.JOINT, q0 + [4.0, 0, 0, 0, 0, 0],
                              relative=False, straight=False, speed_percent=None)
    print(f"{trajectory.duration:.1f} s planned in {time.perf_counter() - start:.2f} s")
    assert 600.0 <= trajectory.duration < MAX_MOTION_SECONDS
    assert len(trajectory) == round(trajectory.duration / 0.004) + 1
