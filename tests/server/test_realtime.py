"""The product as `make run` starts it: the device server with its cycle process on the real-time
clock (4 ms), driven from another process over gRPC. Besides a plain move, the loops issue 10
put in the cycle process (the guard of a guarded move, an I/O watch, jog integration with its
deadman, the tool changer's signals): their specs and messages cross the process boundary."""
from __future__ import annotations

import contextlib
import itertools
import subprocess
import sys
import threading

import grpc
import numpy as np
import pytest

from landscape.client import Session
from landscape.v1 import (control_pb2, digital_io_service_pb2, end_effector_pb2,
                          event_service_pb2, motion_pb2, sensing_pb2, settings_pb2, types_pb2)

from support import spawned_server, stubs

LAMP_GREEN = 1 << 3      # unit 2, cell_outputs


@pytest.fixture(scope="module")
def target(tmp_path_factory):
    with spawned_server("--paths", str(tmp_path_factory.mktemp("var") / "paths.sqlite3")) as t:
        yield t


@contextlib.contextmanager
def _active(target):
    """(device stub, I/O stub, event stream) of an active arm, locked by a session of ours."""
    with grpc.insecure_channel(target) as channel, Session(channel, "realtime") as session:
        device, io, events = stubs(session.channel)
        stream = events.Subscribe(event_service_pb2.SubscribeRequest())
        session.lock()
        device.Activate(control_pb2.ActivateRequest(), timeout=10)
        try:
            yield device, io, stream
        finally:
            stream.cancel()
            # Hand the arm back as it was found: drives off, lock released (the next test's
            # session locks it at once).
            state = device.GetDeviceState(control_pb2.GetDeviceStateRequest()).state
            if state == types_pb2.DEVICE_STATE_RESTING:
                device.Deactivate(control_pb2.DeactivateRequest(), timeout=10)
            device.Release(control_pb2.ReleaseRequest(), timeout=10)


def _events_until_end(stream, command_id: str) -> list:
    """The events of `command_id` up to its done or failed event."""
    seen = []
    for reply in stream:
        event = reply.event
        if (event.HasField("command") and event.command.command_id == command_id
                or event.HasField("digital_io") and event.digital_io.command_id == command_id):
            seen.append(event)
            if event.event_id in ("command_done", "command_failed"):
                return seen
    raise AssertionError("the event stream ended")


def test_a_move_on_the_real_time_clock(target):
    with _active(target) as (device, _, stream):
        goal = [0.4, -0.1, 1.7, 0.0, 1.2, 0.2]
        reply = device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            point_name="rt", frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME, values=goal, speed=50))
        done = _events_until_end(stream, reply.ret_val.command_id)[-1]
        assert done.event_id == "command_done"
        position = device.GetRobotPosition(settings_pb2.GetRobotPositionRequest())
        assert np.max(np.abs(np.array(position.joint_position) - goal)) < 1e-4
        device.Deactivate(control_pb2.DeactivateRequest(), timeout=10)
        state = device.GetMotionControlState(settings_pb2.GetMotionControlStateRequest())
        assert state.control_mode == "power_off"


def test_the_vacuum_cup_is_fetched_and_returned(target):
    with _active(target) as (device, _, _):
        reply = device.GetTool(end_effector_pb2.GetToolRequest(tool_id="vacuum"), timeout=120)
        assert reply.ret_val.ret_code == types_pb2.RETURN_CODE_CMD_EXEC_OK
        state = device.GetEndEffectorState(end_effector_pb2.GetEndEffectorStateRequest())
        assert (state.current_ee, state.ee_state) == ("vacuum", "off")
        offset = device.GetToolOffsets(settings_pb2.GetToolOffsetsRequest()).offset
        assert offset.z == pytest.approx(0.12)          # the cup's tip (cell file)
        device.PutTool(end_effector_pb2.PutToolRequest(tool_id="vacuum"), timeout=120)
        state = device.GetEndEffectorState(end_effector_pb2.GetEndEffectorStateRequest())
        assert state.current_ee == ""


def test_move_react_in_free_air_runs_its_full_distance(target):
    with _active(target) as (device, _, stream):
        before = device.GetRobotPosition(settings_pb2.GetRobotPositionRequest()).world_position
        reply = device.MoveReact(sensing_pb2.MoveReactRequest(
            sensor_type="force_sensor", motion=types_pb2.Vector3(z=-0.05), speed=2,
            thresholds=types_pb2.Vector3(z=-20)), timeout=30)
        done = _events_until_end(stream, reply.ret_val.command_id)[-1]
        assert done.event_id == "command_done"
        assert done.command.message == "not triggered: moved the full distance"
        after = device.GetRobotPosition(settings_pb2.GetRobotPositionRequest()).world_position
        assert after.z - before.z == pytest.approx(0.05, abs=1e-4)   # up: the flange's -z


def test_a_digital_io_watch_signals_its_bits(target):
    with _active(target) as (_, io, stream):
        io.SetDigitalIO(digital_io_service_pb2.SetDigitalIORequest(
            type="output", unit_id=2, bits_off=LAMP_GREEN))
        reply = io.SignalDigitalIO(digital_io_service_pb2.SignalDigitalIORequest(
            type="output", unit_id=2, bit_string=LAMP_GREEN, polling_timeout=10000,
            callback_type=digital_io_service_pb2.CALLBACK_TYPE_CLIENT_EVENT))
        io.SetDigitalIO(digital_io_service_pb2.SetDigitalIORequest(
            type="output", unit_id=2, bits_on=LAMP_GREEN))
        events = _events_until_end(stream, reply.ret_val.command_id)
        assert [e.event_id for e in events][-2:] == ["digital_io", "command_done"]
        assert events[-2].digital_io.bits_on & LAMP_GREEN
        io.SetDigitalIO(digital_io_service_pb2.SetDigitalIORequest(
            type="output", unit_id=2, bits_off=LAMP_GREEN))


def test_a_jog_ends_on_the_deadman(target):
    with _active(target) as (device, _, _):
        device.ManualControl(sensing_pb2.ManualControlRequest(
            type=sensing_pb2.MANUAL_CONTROL_TYPE_TEACHPENDANT), timeout=5)
        start = np.array(device.GetRobotPosition(
            settings_pb2.GetRobotPositionRequest()).joint_position)
        silence = threading.Event()

        def five_then_silence():   # the stream stays open, nothing more comes
            yield from itertools.repeat(sensing_pb2.JogRequest(
                deadman=True, frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME,
                velocity=[0, 0, 0, 0, 0, 20]), 5)
            silence.wait(10)
        replies = []
        with pytest.raises(grpc.RpcError) as ended:
            for reply in device.Jog(five_then_silence(), timeout=30):
                replies.append(reply)
        silence.set()
        assert ended.value.code() is grpc.StatusCode.ABORTED
        assert "deadman" in ended.value.details()
        assert replies
        moved = np.array(device.GetRobotPosition(
            settings_pb2.GetRobotPositionRequest()).joint_position) - start
        assert moved[5] > 0 and np.abs(moved[:5]).max() < 1e-4
        device.ManualControl(sensing_pb2.ManualControlRequest(
            type=sensing_pb2.MANUAL_CONTROL_TYPE_OFF), timeout=5)
def test_the_collision_margin_is_set_on_the_command_line(tmp_path):
    """--collision-margin 0.02: a move ending 1.5 cm over the table (clear at the default 5 mm)
    is refused; a margin that is no margin is refused at start with a clear message."""
    with spawned_server("--paths", str(tmp_path / "paths.sqlite3"),
                        "--collision-margin", "0.02") as target, \
            grpc.insecure_channel(target) as channel, Session(channel, "margin") as session:
        device, _, _ = stubs(session.channel)
        session.lock()
        device.Activate(control_pb2.ActivateRequest(), timeout=10)
        with pytest.raises(grpc.RpcError) as refused:
            device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
                frame=types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME,
                values=[0.65, 0.3, 0.215, np.pi, 0, 0]), timeout=30)
        assert refused.value.code() is grpc.StatusCode.FAILED_PRECONDITION
        assert "table" in refused.value.details()
        device.Deactivate(control_pb2.DeactivateRequest(), timeout=10)
    bad = subprocess.run([sys.executable, "-m", "landscape.server", "--collision-margin", "0"],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2 and "--collision-margin must be above 0" in bad.stderr
