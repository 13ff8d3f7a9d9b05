"""Issue 9 item 4 for Cartesian targets: a target far beyond the arm (1e6, 1e12, 1e300 m) is
refused OUT_OF_RANGE, naming the field and the bound, before any sample of the path is made;
nothing moves, nothing is stored, the server keeps serving. Straight moves, arcs and straight
paths, in the base and the world frame.

The server runs in this process under a memory cap (support.memory_cap): before the bounds,
these requests allocated terabytes (MemoryError, INTERNAL) or grew the process until the kernel
killed it; a regression now fails the test instead of exhausting the machine."""
from __future__ import annotations

import grpc
import numpy as np
import pytest

from landscape.server.planning.motion.cartesian import MAX_SAMPLES, straight_line
from landscape.server.planning.motion.trajectory import PlanningError
from landscape.server.device.states import State
from landscape.server.planning.targets import MAX_ANGLE, MAX_POSITION, reach
from landscape.robot.units import pose_vector
from landscape.v1 import motion_pb2, types_pb2

from support import Arm, assert_serving, error_info, memory_cap

BASE = types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME
WORLD = types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME
STRAIGHT = types_pb2.MOTION_TYPE_STRAIGHT_MOTION
ABSOLUTE = types_pb2.OFFSET_TYPE_ABSOLUTE_DATA
RELATIVE = types_pb2.OFFSET_TYPE_RELATIVE_DATA
FRAMES = [pytest.param(BASE, id="base"), pytest.param(WORLD, id="world")]
FAR = [1e6, 1e12, 1e300]
pytestmark = pytest.mark.usefixtures("memory_capped")


@pytest.fixture(scope="module")
def arm(tmp_path_factory):
    a = Arm(tmp_path_factory.mktemp("bounds"))
    yield a
    a.close()


def refused(arm, call, field: str) -> str:
    """call() is refused OUT_OF_RANGE naming `field` and its maximum; nothing moved or was
    stored; the server is SERVING. Returns the message."""
    device = arm.server.device
    before, paths = arm.joints().copy(), dict(device.path_runs.paths.items())
    with pytest.raises(grpc.RpcError) as error:
        call()
    assert error.value.code() is grpc.StatusCode.OUT_OF_RANGE, error.value.details()
    info = error_info(error.value)
    assert info.metadata["field"] == field and "maximum" in info.metadata, dict(info.metadata)
    assert device.state is State.RESTING
    assert np.max(np.abs(arm.joints() - before)) < 1e-9
    assert dict(device.path_runs.paths.items()) == paths
    assert_serving(arm.session.channel)
    return error.value.details()


def here(arm) -> list[float]:
    """Where the tool tip is, x, y, z (m), roll, pitch, yaw (rad), base = world here."""
    return list(np.concatenate(pose_vector(arm.tool_tip())))


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("far", FAR)
def test_straight_moves_far_away_are_refused(arm, frame, far):
    goal = here(arm)
    goal[0] = far
    refused(arm, lambda: arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        frame=frame, values=goal, motion_type=STRAIGHT), timeout=30), "values")
    refused(arm, lambda: arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
        frame=frame, values=[far, 0, 0, 0, 0, 0], motion_type=STRAIGHT), timeout=30), "values")


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("far", FAR)
def test_arcs_through_or_to_far_points_are_refused(arm, frame, far):
    near = [0.05, 0.05, 0, 0, 0, 0]
    for offset_type in (RELATIVE, ABSOLUTE):
        for via, goal, field in (([far, far, 0, 0, 0, 0], [2 * far, 0, 0, 0, 0, 0], "arc_value"),
                                 (near, [far, 0, 0, 0, 0, 0], "goal_value")):
            refused(arm, lambda: arm.device.MoveArc(motion_pb2.MoveArcRequest(
                frame=frame, offset_type=offset_type, arc_value=via, goal_value=goal),
                timeout=30), field)


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("far", FAR)
def test_straight_paths_to_far_points_are_refused_at_load(arm, frame, far):
    start = here(arm)
    for offset_type, point in ((ABSOLUTE, [far, *start[1:]]), (RELATIVE, [far, 0, 0, 0, 0, 0])):
        first = start if offset_type is ABSOLUTE else [0.0] * 6
        tags = [types_pb2.TagStruct(**dict(zip(("x", "y", "z", "roll", "pitch", "yaw"), v)))
                for v in (first, point)]
        header = motion_pb2.PathHeader(path_name="far", frame=frame, motion_type=STRAIGHT,
                                       offset_type=offset_type, number_of_points=2)
        message = refused(arm, lambda: arm.device.PathLoad(iter([motion_pb2.PathLoadRequest(
            header=header, tags=tags)]), timeout=30), "tags")
        assert message.startswith("point 1:"), message


def test_a_target_within_the_value_bounds_but_out_of_reach_names_the_reach(arm):
    """5 m is a legal coordinate (a world frame may be 100 m away) but no TX90 gets there."""
    goal = here(arm)
    goal[0] = 5.0
    message = refused(arm, lambda: arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        frame=BASE, values=goal, motion_type=STRAIGHT), timeout=30), "values")
    assert f"reaches {reach(arm.server.device.arm)[1]:.4g} m at most" in message


def test_an_arc_on_a_huge_circle_is_refused_before_sampling(arm):
    """Both points within reach, nearly in line with the start, the arc point beyond the goal:
    the circle through them is kilometres round and the arc goes most of the way round it."""
    refused(arm, lambda: arm.device.MoveArc(motion_pb2.MoveArcRequest(
        frame=BASE, offset_type=RELATIVE, arc_value=[0.2, 1e-7, 0, 0, 0, 0],
        goal_value=[0.1, 0, 0, 0, 0, 0]), timeout=30), "arc_value")


def test_pose_angles_are_bounded_to_a_turn(arm):
    message = refused(arm, lambda: arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
        frame=BASE, values=[0, 0, 0, 0, 0, 1e12], motion_type=STRAIGHT), timeout=30),
        "values")
    assert f"{MAX_ANGLE:.6g} rad" in message
    assert MAX_POSITION >= 100.0 + reach(arm.server.device.arm)[1]   # a world frame's bound


def test_a_line_needing_too_many_samples_is_refused_before_any_is_made(arm):
    kin, q = arm.kin, arm.joints()
    goal = kin.forward(q)
    goal[0, 3] += 0.1
    with memory_cap(headroom=256 << 20):
        with pytest.raises(PlanningError) as error:
            straight_line(kin, q, goal, max_step=0.1 / (10 * MAX_SAMPLES))
    assert error.value.reason == "TOO_MANY_SAMPLES"
    assert straight_line(kin, q, goal).shape[0] == 21
