"""The product as `make run` starts it: the device server with its cycle process on the real-time
clock (4 ms), driven from another process over gRPC."""
from __future__ import annotations

import subprocess
import sys

import grpc
import numpy as np
import pytest

from landscape.client import Session
from landscape.v1 import control_pb2, event_service_pb2, motion_pb2, settings_pb2, types_pb2

from support import spawned_server, stubs


@pytest.fixture(scope="module")
def target(tmp_path_factory):
    with spawned_server("--paths", str(tmp_path_factory.mktemp("var") / "paths.sqlite3")) as t:
        yield t


def test_a_move_on_the_real_time_clock(target):
    with grpc.insecure_channel(target) as channel, Session(channel, "realtime") as session:
        device, _, events = stubs(session.channel)
        stream = events.Subscribe(event_service_pb2.SubscribeRequest())
        session.lock()
        device.Activate(control_pb2.ActivateRequest(), timeout=10)
        goal = [0.4, -0.1, 1.7, 0.0, 1.2, 0.2]
        reply = device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            point_name="rt", frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME, values=goal, speed=50))
        done = next(r.event for r in stream if r.event.HasField("command")
                    and r.event.command.command_id == reply.ret_val.command_id
                    and r.event.event_id in ("command_done", "command_failed"))
        stream.cancel()
        assert done.event_id == "command_done"
        position = device.GetRobotPosition(settings_pb2.GetRobotPositionRequest())
        assert np.max(np.abs(np.array(position.joint_position) - goal)) < 1e-4
        device.Deactivate(control_pb2.DeactivateRequest(), timeout=10)
        state = device.GetMotionControlState(settings_pb2.GetMotionControlStateRequest())
        assert state.control_mode == "power_off"


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
