"""Issue 29 item 1: the cell live in Foxglove. A client speaking the Foxglove WebSocket
protocol (foxglove_client.py) subscribes and receives every link's transform while the arm
moves, the tool pose, the joints, the I/O, and events and alarms as Log messages; it fetches
the URDF; it can change nothing."""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from landscape.bridges.foxglove.server import FoxgloveBridge, parse_args
from landscape.robot.kinematics import Kinematics
from landscape.v1 import control_pb2, motion_pb2, types_pb2

from bridge_support import BridgeThread
from foxglove_client import FoxgloveClient
from support import activate, locked_session, start_server, stubs

TARGET = [1.2, -0.3, 1.9, 0.2, 1.0, 0.4]   # a joint move of several seconds


@pytest.fixture(scope="module")
def cell():
    server = start_server(lockstep_pace=1.0)
    bridge = BridgeThread(lambda: FoxgloveBridge({"arm1": server.target}, port=0, rate_hz=30))
    yield server, bridge
    bridge.close()
    server.stop(grace=None)


@pytest.fixture
def client(cell):
    c = FoxgloveClient(cell[1].bridge.port)
    yield c
    c.close()


def chain(transforms) -> np.ndarray:
    """tool0 in base_link: the link transforms composed, base to flange."""
    pose = pin.SE3.Identity()
    for t in transforms:
        q = t.rotation
        pose = pose * pin.SE3(pin.Quaternion(q.w, q.x, q.y, q.z).matrix(),
                              np.array([t.translation.x, t.translation.y, t.translation.z]))
    return pose.homogeneous


def test_a_client_receives_every_link_s_transform_while_the_arm_moves(cell, client):
    server, _ = cell
    sub = client.subscribe("/arm1/tf")
    poses = client.subscribe("/arm1/tool_pose")
    kin = Kinematics(server.device.arm)
    session = locked_session(server, "foxglove-test")
    try:
        activate(session)
        device, _, _ = stubs(session.channel)
        device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME, values=TARGET), timeout=30)
        flanges, stamps = [], []
        for log_time, message in client.messages(sub):
            pairs = [(t.parent_frame_id, t.child_frame_id) for t in message.transforms]
            assert pairs[0] == ("arm1/base_link", "arm1/link1") and len(pairs) == 7
            assert pairs[-1] == ("arm1/link6", "arm1/tool0")
            flanges.append(chain(message.transforms))
            stamps.append(log_time)
            if np.allclose(flanges[-1], kin.forward(np.array(TARGET)), atol=1e-4):
                break
            assert len(flanges) < 30 * 60, "the arm never arrived in Foxglove's view"
    finally:
        session.close()
    # it moved through the view: many distinct poses, thinned to about 30 a second
    assert len(flanges) > 10
    assert np.linalg.norm(flanges[0][:3, 3] - flanges[-1][:3, 3]) > 0.1
    rate = (len(stamps) - 1) / ((stamps[-1] - stamps[0]) / 1e9)
    assert 10 < rate < 40, rate
    _, pose = next(client.messages(poses))
    assert pose.frame_id == "arm1/base_link"


def test_the_urdf_is_served_as_an_asset_a_parameter_and_a_topic(cell, client):
    status, urdf = client.fetch_asset("package://landscape/arm1.urdf")
    assert status == 0 and b'<link name="arm1/link6"' in urdf
    status, error = client.fetch_asset("package://landscape/../../etc/passwd.urdf", 2)
    assert status != 0
    assert client.parameters()["/arm1/robot_description"] == urdf.decode()
    sub = client.subscribe("/arm1/robot_description")
    _, message = next(client.messages(sub))
    assert message["data"] == urdf.decode()


def test_the_bridge_is_read_only(cell, client):
    client.channel("/arm1/tf")
    capabilities = set(client.info["capabilities"])
    assert not capabilities & {"clientPublish", "services", "connectionGraph"}
    before = client.parameters()
    after = client.parameters(set_values={"/arm1/robot_description": "<robot/>"})
    assert after == before


def test_events_and_alarms_arrive_as_log_messages_and_the_io_as_its_units(cell, client):
    server, _ = cell
    logs = client.subscribe("/arm1/log")
    io = client.subscribe("/arm1/digital_io")
    _, units = next(client.messages(io))
    assert units["units"] and {"name", "type", "bits_on", "bits"} <= set(units["units"][0])
    device, _, _ = stubs_for(server)
    device.OperatePanel(control_pb2.OperatePanelRequest(
        action=control_pb2.PANEL_ACTION_PRESS_ESTOP), timeout=10)
    try:
        seen = []
        for _, message in client.messages(logs):
            seen.append(message)
            if message.message.startswith("alarm"):
                break
        alarm = seen[-1]
        assert alarm.level >= 4, alarm          # foxglove.Log: WARNING 3, ERROR 4, FATAL 5
        assert "e-stop" in alarm.message.lower() or "estop" in alarm.message.lower()
    finally:
        device.OperatePanel(control_pb2.OperatePanelRequest(
            action=control_pb2.PANEL_ACTION_RELEASE_ESTOP), timeout=10)
        device.Reset(control_pb2.ResetRequest(), timeout=10)


def stubs_for(server):
    import grpc
    return stubs(grpc.insecure_channel(server.target))


def test_off_loopback_it_needs_to_be_told():
    with pytest.raises(SystemExit):
        parse_args(["--device", "arm1=127.0.0.1:50051", "--host", "0.0.0.0"])
    args, devices = parse_args(["--device", "arm1=127.0.0.1:50051", "--host", "0.0.0.0",
                                "--insecure"])
    assert devices == {"arm1": "127.0.0.1:50051"} and not math.isnan(args.rate)
