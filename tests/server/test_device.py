"""The device core through gRPC: the lock, the disconnect handler, settings, units, e-stop and
RSVP, against a real server and the simulated arm on the lock-step clock."""
from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time

import grpc
import numpy as np
import pytest

from landscape.client import Session
from landscape.server.events import alarms
from landscape.server.device.states import State
from landscape.robot.controller import EnableState
from landscape.v1 import control_pb2, event_service_pb2, settings_pb2, types_pb2

from support import (HOLDER_SCRIPT, activate, bus_history, error_info, locked_session, stubs,
                     wait_until)


@pytest.fixture
def holder(server):
    session = locked_session(server, "holder")
    yield session
    session.close()


def test_only_the_lock_holder_commands_and_the_other_still_reads(server, holder):
    other = Session(grpc.insecure_channel(server.target), "observer").open()
    try:
        device, _, events = stubs(other.channel)
        with pytest.raises(grpc.RpcError) as refused:
            device.Lock(control_pb2.LockRequest(session_id=other.session_id,
                                                session_secret=other.session_secret), timeout=5)
        assert refused.value.code() is grpc.StatusCode.FAILED_PRECONDITION
        for call in (lambda: device.SetSpeed(settings_pb2.SetSpeedRequest(
                         speed=50, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED), timeout=5),
                     lambda: device.Activate(control_pb2.ActivateRequest(), timeout=5),
                     lambda: device.Release(control_pb2.ReleaseRequest(), timeout=5)):
            with pytest.raises(grpc.RpcError) as refused:
                call()
            assert refused.value.code() is grpc.StatusCode.PERMISSION_DENIED
            assert error_info(refused.value).reason == "NOT_LOCK_HOLDER"
        assert server.device.settings.speed_percent == 25.0 and server.device.state is State.INACTIVE

        # The observer reads state and events while the holder commands.
        subscription = events.Subscribe(event_service_pb2.SubscribeRequest(), timeout=10)
        status = device.GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=5)
        assert (status.locked, status.lock_holder) == (True, "holder")
        activate(holder)
        change = next(e for e in (r.event for r in subscription) if e.HasField("state_change"))
        assert (change.state_change.from_state, change.state_change.to_state) == ("inactive", "resting")
        subscription.cancel()
        position = device.GetRobotPosition(settings_pb2.GetRobotPositionRequest(), timeout=5)
        assert len(position.joint_position) == 6
    finally:
        other.close()


def test_a_killed_lock_holder_leaves_the_arm_disabled_and_the_lock_free(server):
    proc = subprocess.Popen([sys.executable, "-c", HOLDER_SCRIPT, server.target],
                            stdout=subprocess.PIPE, text=True)
    try:
        assert proc.stdout.readline().strip() == "active"
        assert server.device.state is State.RESTING
        assert server.device.feedback().enable is EnableState.ENABLED
        os.kill(proc.pid, signal.SIGKILL)
        killed = time.monotonic()
        proc.wait(timeout=5)
        wait_until(lambda: server.device.state is State.UNLOCKED
                   and server.device.feedback().enable is EnableState.DISABLED, timeout=5)
        elapsed = time.monotonic() - killed
        print(f"disabled and unlocked {elapsed * 1000:.0f} ms after SIGKILL")   # bench_faults.py
    finally:
        proc.kill()
    alarms = [e for e in bus_history(server) if e.event_id == "alarm"]
    assert any("doomed disconnected" in e.detail.message for e in alarms)
    successor = locked_session(server, "next")
    assert server.device.status().lock_holder == "next"
    successor.close()



def test_a_session_without_keepalives_ends_and_releases(server):
    server.device.sessions.keepalive_timeout = 0.3
    channel = grpc.insecure_channel(server.target)
    session = Session(channel, "silent").open()
    session._interval = 3600  # stops sending keep-alives: the server must end it
    session.lock()
    wait_until(lambda: server.device.state is State.UNLOCKED, timeout=5)
    session.close()


def test_a_pose_read_in_millimeters_and_degrees_is_the_same_pose(server, holder):
    device, _, _ = stubs(holder.channel)
    si = device.GetRobotPosition(settings_pb2.GetRobotPositionRequest(), timeout=5)
    device.SetUnits(settings_pb2.SetUnitsRequest(linear_units=types_pb2.LINEAR_UNIT_MILLIMETERS,
                                                 angular_units=types_pb2.ANGULAR_UNIT_DEGREES))
    mm = device.GetRobotPosition(settings_pb2.GetRobotPositionRequest(), timeout=5)
    assert np.allclose(np.radians(mm.joint_position), si.joint_position, atol=1e-12)
    p, q = si.world_position, mm.world_position
    assert np.allclose([q.x, q.y, q.z], np.array([p.x, p.y, p.z]) * 1000, atol=1e-9)
    assert np.allclose(np.radians([q.roll, q.pitch, q.yaw]), [p.roll, p.pitch, p.yaw], atol=1e-12)
    units = device.GetUnits(settings_pb2.GetUnitsRequest(), timeout=5)
    assert (units.linear_units, units.angular_units) == (types_pb2.LINEAR_UNIT_MILLIMETERS,
                                                         types_pb2.ANGULAR_UNIT_DEGREES)


def test_tool_offset_and_world_frame_move_the_reported_tool_tip(server, holder):
    device, _, _ = stubs(holder.channel)
    before = device.GetRobotPosition(settings_pb2.GetRobotPositionRequest()).world_position
    device.SetToolOffset(settings_pb2.SetToolOffsetRequest(offset=types_pb2.Pose(z=0.2)))
    device.SetWorldCartesianFrame(settings_pb2.SetWorldCartesianFrameRequest(
        frame=types_pb2.Pose(x=1.0, yaw=math.pi / 2)))
    after = device.GetRobotPosition(settings_pb2.GetRobotPositionRequest()).world_position
    # Tool z points down at this pose (roll = pi), so the tip is 0.2 m lower; the world is
    # 1 m along base x and turned 90 deg: base (x, y) is world (y, 1 - x).
    assert after.z == pytest.approx(before.z - 0.2, abs=1e-6)
    assert (after.x, after.y) == pytest.approx((before.y, 1.0 - before.x), abs=1e-6)
    offset = device.GetToolOffsets(settings_pb2.GetToolOffsetsRequest()).offset
    assert (offset.x, offset.y, offset.z) == pytest.approx((0, 0, 0.2))


BAD_SPEEDS = [
    (math.nan, types_pb2.SPEED_TYPE_PERCENT_SPEED, grpc.StatusCode.INVALID_ARGUMENT, "-2"),
    (math.inf, types_pb2.SPEED_TYPE_LINEAR_SPEED, grpc.StatusCode.INVALID_ARGUMENT, "-2"),
    (-5, types_pb2.SPEED_TYPE_PERCENT_SPEED, grpc.StatusCode.OUT_OF_RANGE, "-3"),
    (0, types_pb2.SPEED_TYPE_ANGULAR_SPEED, grpc.StatusCode.OUT_OF_RANGE, "-3"),
    (100.5, types_pb2.SPEED_TYPE_PERCENT_SPEED, grpc.StatusCode.OUT_OF_RANGE, "-3"),
    (2.5, types_pb2.SPEED_TYPE_LINEAR_SPEED, grpc.StatusCode.OUT_OF_RANGE, "-3"),
    (50, types_pb2.SPEED_TYPE_UNSPECIFIED, grpc.StatusCode.INVALID_ARGUMENT, "-2"),
]


@pytest.mark.parametrize("value, kind, code, ret_code", BAD_SPEEDS)
def test_bad_speeds_are_refused_and_change_nothing(server, holder, value, kind, code, ret_code):
    device, _, _ = stubs(holder.channel)
    before = device.GetVelocities(settings_pb2.GetVelocitiesRequest())
    with pytest.raises(grpc.RpcError) as refused:
        device.SetSpeed(settings_pb2.SetSpeedRequest(speed=value, attribute=kind), timeout=5)
    assert refused.value.code() is code
    assert error_info(refused.value).metadata["ret_code"] == ret_code
    assert device.GetVelocities(settings_pb2.GetVelocitiesRequest()) == before


def test_settings_are_reflected_in_their_gets_in_the_current_units(server, holder):
    device, _, _ = stubs(holder.channel)
    device.SetSpeed(settings_pb2.SetSpeedRequest(speed=40, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED))
    device.SetSpeed(settings_pb2.SetSpeedRequest(speed=0.5, attribute=types_pb2.SPEED_TYPE_LINEAR_SPEED))
    device.SetAcceleration(settings_pb2.SetAccelerationRequest(
        accel=2.0, attribute=types_pb2.ACCEL_TYPE_ANGULAR_ACCEL))
    device.SetUnits(settings_pb2.SetUnitsRequest(linear_units=types_pb2.LINEAR_UNIT_INCHES,
                                                 angular_units=types_pb2.ANGULAR_UNIT_DEGREES))
    velocities = device.GetVelocities(settings_pb2.GetVelocitiesRequest())
    assert velocities.percent_velocity == 40
    assert velocities.world_linear_velocity == pytest.approx(0.5 / 0.0254)
    maxima = device.GetMaxVelocities(settings_pb2.GetMaxVelocitiesRequest())
    assert np.allclose(velocities.joint_velocities, np.array(maxima.max_joint_velocities) * 0.4)
    assert maxima.max_joint_velocities[0] == pytest.approx(400.0)  # TX90 J1, deg/s
    accels = device.GetAccelerations(settings_pb2.GetAccelerationsRequest())
    assert accels.world_angular_accel == pytest.approx(math.degrees(2.0))


def _active_holder(server, choice: str, answers: list) -> Session:
    """A lock holder with the drives on, who answers every question `choice` (noted)."""
    def answer(request):
        answers.append(request)
        return choice, list(request.data)

    session = Session(grpc.insecure_channel(server.target), "operator", on_rsvp=answer).open()
    session.lock()
    activate(session)
    return session


def test_estop_faults_the_device_and_reset_needs_it_released_then_asks_the_holder(server):
    answers = []
    session = _active_holder(server, "reset", answers)
    try:
        device, _, _ = stubs(session.channel)
        server.link.between_cycles(lambda c: c.panel.press_estop())
        wait_until(lambda: server.device.state is State.ERROR)
        assert server.device.feedback().enable is not EnableState.ENABLED
        state = device.GetMotionControlState(settings_pb2.GetMotionControlStateRequest())
        assert (state.motion_control_state, state.control_mode) == ("robot_stopped_on_error",
                                                                     "controller_error")
        with pytest.raises(grpc.RpcError) as refused:
            device.Reset(control_pb2.ResetRequest(), timeout=5)
        assert error_info(refused.value).reason == "ESTOP_ACTIVE"

        server.link.between_cycles(lambda c: c.panel.release_estop())
        wait_until(lambda: server.device.state is State.INACTIVE)  # the holder answered "reset"
        assert answers[0].event_id == "estop_released" and list(answers[0].choices) == ["reset", "stay"]
        kinds = [e.event_id for e in bus_history(server)]
        assert kinds.index("rsvp_request") < kinds.index("rsvp_answer")
        assert any(e.event_id == "alarm" and e.detail.code == 102 for e in bus_history(server))
    finally:
        session.close()


def test_an_estop_pressed_and_released_between_two_cycles_is_still_an_estop(server):
    """Found by the page's test on a busy machine: the release came before any cycle saw the
    press, so the device took it for a plain controller error and asked nothing. A press lasts
    at least the cycle after it, as a safety relay's does."""
    answers = []
    session = _active_holder(server, "stay", answers)
    try:
        server.link.between_cycles(lambda c: (c.panel.press_estop(), c.panel.release_estop()))
        wait_until(lambda: answers, timeout=10)          # asked, after the release
        assert answers[0].event_id == "estop_released"
        assert server.device.state is State.ERROR        # the holder said stay
        assert any(e.event_id == "alarm" and e.detail.code == alarms.ESTOP
                   for e in bus_history(server))
    finally:
        session.close()


def test_an_unanswered_rsvp_takes_its_default(server):
    server.device.rsvp_timeout = 0.2
    session = locked_session(server, "absent")  # answers nothing
    try:
        server.link.between_cycles(lambda c: c.panel.press_estop())
        wait_until(lambda: server.device.state is State.ERROR)
        server.link.between_cycles(lambda c: c.panel.release_estop())
        wait_until(lambda: any(e.event_id == "rsvp_answer" for e in bus_history(server)))
        answer = next(e for e in bus_history(server) if e.event_id == "rsvp_answer").detail
        assert (answer.choice, answer.timed_out) == ("stay", True)
        assert server.device.state is State.ERROR
    finally:
        session.close()
