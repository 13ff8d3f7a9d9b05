"""Bad input gets a clear error, changes nothing, and the server goes on serving."""
from __future__ import annotations

import math

import grpc
import numpy as np
import pytest

from landscape.client import Session
from landscape.server.planning.path_planning import MAX_POINTS
from landscape.server.device.states import State
from landscape.v1 import (control_pb2, device_service_pb2_grpc, motion_pb2, session_service_pb2,
                          session_service_pb2_grpc)
from landscape.v1 import settings_pb2, types_pb2

from support import Arm, error_info

JOINT, BASE = types_pb2.REFERENCE_FRAME_JOINT_FRAME, types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME


@pytest.fixture
def arm(tmp_path, backend):
    a = Arm(tmp_path, backend=backend)
    yield a
    a.close()


def refused(call) -> grpc.RpcError:
    with pytest.raises(grpc.RpcError) as error:
        call()
    return error.value


def header(name, n, frame=JOINT):
    return motion_pb2.PathHeader(path_name=name, frame=frame,
                                 motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                 offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA, number_of_points=n)


@pytest.mark.parametrize("request_, code", [
    (motion_pb2.MoveAbsoluteRequest(frame=JOINT, values=[0, 0, 1.5, 0, 1.5, 0], speed=0),
     grpc.StatusCode.OUT_OF_RANGE),
    (motion_pb2.MoveAbsoluteRequest(frame=JOINT, values=[0, 0, 1.5, 0, 1.5, 0], speed=150),
     grpc.StatusCode.OUT_OF_RANGE),
    (motion_pb2.MoveAbsoluteRequest(frame=JOINT, values=[0, 0, 1.5, 0, 1.5, 0],
                                    speed=math.nan), grpc.StatusCode.INVALID_ARGUMENT),
    (motion_pb2.MoveAbsoluteRequest(frame=types_pb2.REFERENCE_FRAME_UNSPECIFIED,
                                    values=[0] * 6), grpc.StatusCode.INVALID_ARGUMENT),
    (motion_pb2.MoveAbsoluteRequest(frame=JOINT, values=[0] * 6,
                                    motion_type=types_pb2.MOTION_TYPE_SLEW_MOTION),
     grpc.StatusCode.INVALID_ARGUMENT),
    (motion_pb2.MoveAbsoluteRequest(frame=JOINT, values=[0, 0, 1.5, 0, 1.5, math.inf]),
     grpc.StatusCode.INVALID_ARGUMENT),
])
def test_bad_moves_are_refused_and_nothing_moves(arm, request_, code):
    before = arm.joints().copy()
    assert refused(lambda: arm.device.MoveAbsolute(request_, timeout=5)).code() is code
    assert arm.server.device.state is State.RESTING
    assert np.max(np.abs(arm.joints() - before)) < 1e-6


@pytest.mark.parametrize("offset, code", [
    (types_pb2.Pose(z=math.inf), grpc.StatusCode.INVALID_ARGUMENT),
    (types_pb2.Pose(x=5.0), grpc.StatusCode.OUT_OF_RANGE),
])
def test_bad_tool_offsets_are_refused(arm, offset, code):
    before = arm.server.device.settings
    error = refused(lambda: arm.device.SetToolOffset(settings_pb2.SetToolOffsetRequest(offset=offset)))
    assert error.code() is code
    assert arm.server.device.settings is before


def test_bad_path_points_name_their_index_and_store_nothing(arm):
    tags = [types_pb2.TagStruct(joint_values=[0.1 * i, 0, 1.5, 0, 1.5, 0]) for i in range(6)]
    tags[4].joint_values[2] = math.nan
    error = refused(lambda: arm.device.PathLoad(iter([motion_pb2.PathLoadRequest(
        header=header("nan", 6), tags=tags)])))
    assert error.code() is grpc.StatusCode.INVALID_ARGUMENT
    assert error_info(error).metadata["index"] == "4"
    tags[4].joint_values[2] = 1.5
    tags[5].joint_values.extend([0.0] * 18)   # 24 values for a 6-joint arm
    error = refused(lambda: arm.device.PathLoad(iter([motion_pb2.PathLoadRequest(
        header=header("long", 6), tags=tags)])))
    assert error.code() is grpc.StatusCode.INVALID_ARGUMENT
    assert error_info(error).metadata["index"] == "5"
    tags[1].speed = 300
    error = refused(lambda: arm.device.PathLoad(iter([motion_pb2.PathLoadRequest(
        header=header("fast", 5), tags=tags[:5])])))
    assert error.code() is grpc.StatusCode.OUT_OF_RANGE
    assert arm.server.device.path_runs.paths == {}


def test_a_stream_without_header_or_with_too_many_points_is_refused(arm):
    point = types_pb2.TagStruct(joint_values=[0, 0, 1.5, 0, 1.5, 0])
    error = refused(lambda: arm.device.PathLoad(iter([motion_pb2.PathLoadRequest(tags=[point])])))
    assert error.code() is grpc.StatusCode.INVALID_ARGUMENT

    def flood():
        yield motion_pb2.PathLoadRequest(header=header("flood", 0))
        while True:   # an endless stream: refused once it passes the cap
            yield motion_pb2.PathLoadRequest(tags=[point] * 10_000)
    error = refused(lambda: arm.device.PathLoad(flood(), timeout=60))
    assert error.code() is grpc.StatusCode.OUT_OF_RANGE
    assert str(MAX_POINTS) in error.details()
    assert arm.server.device.path_runs.paths == {}


def test_a_path_move_with_negative_cycles_is_refused(arm):
    arm.device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header("p", 2), tags=[
        types_pb2.TagStruct(joint_values=[0, 0, 1.5, 0, 1.5, 0]),
        types_pb2.TagStruct(joint_values=[0.2, 0, 1.5, 0, 1.5, 0])])]))
    error = refused(lambda: arm.device.PathMove(motion_pb2.PathMoveRequest(
        path_name="p", number_of_cycles=-1)))
    assert error.code() is grpc.StatusCode.OUT_OF_RANGE
    assert arm.server.device.state is State.RESTING


def test_bad_sessions_and_locks_are_refused(arm):
    device = arm.device
    error = refused(lambda: device.Release(control_pb2.ReleaseRequest()))
    assert error.code() is grpc.StatusCode.FAILED_PRECONDITION   # Release needs Inactive
    with grpc.insecure_channel(arm.server.target) as channel:
        connect = session_service_pb2_grpc.SessionServiceStub(channel).Connect
        error = refused(lambda: next(connect(iter([session_service_pb2.ConnectRequest(
            keep_alive=session_service_pb2.KeepAlive())]), timeout=5)))
        assert error.code() is grpc.StatusCode.INVALID_ARGUMENT   # no hello first
    arm.device.Deactivate(control_pb2.DeactivateRequest())
    arm.device.Release(control_pb2.ReleaseRequest())
    with grpc.insecure_channel(arm.server.target) as channel:
        error = refused(lambda: Session(channel, "x").open() and device.Lock(
            control_pb2.LockRequest(session_id="no-such-session")))
        assert error.code() is grpc.StatusCode.INVALID_ARGUMENT
    assert arm.server.device.state is State.UNLOCKED


def test_lock_needs_the_sessions_secret_not_just_its_id(server):
    """Issue 9.6: a client that knows another session's id cannot lock with it."""
    with grpc.insecure_channel(server.target) as channel:
        owner = Session(channel, "owner").open()
        try:
            device = device_service_pb2_grpc.DeviceServiceStub(channel)
            for secret in ("", "guess", owner.session_secret[:-1]):
                error = refused(lambda: device.Lock(control_pb2.LockRequest(
                    session_id=owner.session_id, session_secret=secret)))
                assert error.code() is grpc.StatusCode.INVALID_ARGUMENT
                assert server.device.state is State.UNLOCKED
            reply = device.Lock(control_pb2.LockRequest(
                session_id=owner.session_id, session_secret=owner.session_secret), timeout=5)
            assert reply.lease and reply.ret_val.ret_msg == "locked"
        finally:
            owner.close()


def test_strings_and_lists_beyond_their_bounds_are_refused_before_anything_happens(arm):
    """Issue 9.5: a 2.5 MB point name used to be accepted and published to every subscriber."""
    error = refused(lambda: arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        point_name="p" * 2_500_000, frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME,
        values=[0.1, 0, 1.5, 0, 1.5, 0])))
    assert error.code() is grpc.StatusCode.INVALID_ARGUMENT
    assert error_info(error).metadata["field"] == "point_name"
    error = refused(lambda: arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        point_name="p" * 257, frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME,
        values=[0.1, 0, 1.5, 0, 1.5, 0])))
    assert error_info(error).metadata["bound"] == "256"
    tags = [types_pb2.TagStruct(joint_values=[0, 0, 1.5, 0, 1.5, 0],
                                aux_commands=["dout gripper_close 1"] * 17)]
    error = refused(lambda: arm.device.PathLoad(iter([motion_pb2.PathLoadRequest(
        header=header("long-aux", 1), tags=tags)])))
    assert error.code() is grpc.StatusCode.OUT_OF_RANGE
    assert error_info(error).metadata["field"] == "tags[0].aux_commands"
    assert arm.server.device.state is State.RESTING and "long-aux" not in arm.server.device.path_runs.paths
    with grpc.insecure_channel(arm.server.target) as channel:
        error = refused(lambda: Session(channel, "n" * 300).open())
        assert error.code() is grpc.StatusCode.INVALID_ARGUMENT


def test_no_event_string_exceeds_its_bound():
    from landscape.server.events.bus import MAX_TEXT, EventBus, Severity
    bus = EventBus()
    event = bus.alarm(Severity.INFO, 1, "x" * 100_000, "id" * 1000)
    assert len(event.detail.message) == MAX_TEXT and event.detail.message.endswith("…")
    assert all(len(d) <= MAX_TEXT for d in event.data)
