"""Stored paths read back (DeviceService.ListPaths, GetPath): what PathLoad stored, its points
resolved to joints, in the device's units; real server, simulated arm on the lock-step clock."""
from __future__ import annotations

import math

import grpc
import numpy as np
import pytest

from landscape.v1 import motion_pb2, settings_pb2, stored_paths_pb2, types_pb2

from support import error_info, start_server, stubs

JOINT, BASE = types_pb2.REFERENCE_FRAME_JOINT_FRAME, types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME
STRAIGHT = types_pb2.MOTION_TYPE_STRAIGHT_MOTION


def load(device, name, tags, frame=JOINT, motion=types_pb2.MOTION_TYPE_JOINT_MOTION):
    head = motion_pb2.PathHeader(path_name=name, frame=frame, motion_type=motion,
                                 offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA,
                                 number_of_points=len(tags))

    def requests():
        yield motion_pb2.PathLoadRequest(header=head, tags=tags[:5000])
        for i in range(5000, len(tags), 5000):
            yield motion_pb2.PathLoadRequest(tags=tags[i:i + 5000])
    return device.PathLoad(requests(), timeout=120)


def get_path(device, name):
    return list(device.GetPath(stored_paths_pb2.GetPathRequest(path_name=name), timeout=60))


def joint_points(n):
    return [types_pb2.TagStruct(joint_values=[0.3 * math.sin(i / 50), 0.1, 1.4, 0.0, 1.2,
                                              0.001 * (i % 7)],
                                tag_name=f"j{i}" if i % 10 == 0 else "", tag_index=i,
                                time_delay=0.5 if i == 3 else 0.0, speed=40.0 if i == 2 else 0.0,
                                aux_commands=["dout gripper_close 1"] if i == 4 else [])
            for i in range(n)]


def test_list_paths_sums_up_each_stored_path_and_get_path_gives_its_joints(arm):
    joints = joint_points(12)
    load(arm.device, "pick", joints)
    arm.device.SetToolOffset(settings_pb2.SetToolOffsetRequest(
        offset=types_pb2.Pose(z=0.1)), timeout=10)
    line = [types_pb2.TagStruct(x=0.55, y=y, z=0.7, roll=math.pi, tag_name=f"l{i}")
            for i, y in enumerate((-0.1, 0.0, 0.1))]
    load(arm.device, "line", line, frame=BASE, motion=STRAIGHT)

    listed = arm.device.ListPaths(stored_paths_pb2.ListPathsRequest(), timeout=10)
    assert [p.name for p in listed.paths] == ["line", "pick"]
    line_summary, pick_summary = listed.paths
    assert (pick_summary.motion_type, pick_summary.number_of_points,
            pick_summary.number_of_tags) == (types_pb2.MOTION_TYPE_JOINT_MOTION, 12, 2)
    assert (line_summary.motion_type, line_summary.number_of_points,
            line_summary.number_of_tags) == (STRAIGHT, 3, 3)
    assert line_summary.tool_offset.z == pytest.approx(0.1)
    assert pick_summary.tool_offset.z == pytest.approx(0.0)
    assert list(listed.unreadable) == []

    (message,) = get_path(arm.device, "pick")
    assert message.path == pick_summary and message.first_point == 0
    assert np.allclose([p.joint_values for p in message.points],
                       [p.joint_values for p in joints])
    for got, sent in zip(message.points, joints):
        assert (got.tag_name, got.tag_index, got.time_delay, got.speed,
                list(got.aux_commands)) == (sent.tag_name, sent.tag_index, sent.time_delay,
                                            sent.speed, list(sent.aux_commands))
    # The Cartesian points come back as the joints the device resolved them to: the tool tip
    # (through the offset they were loaded with) where they were asked to be.
    (message,) = get_path(arm.device, "line")
    get_path_si = message.points
    tcp = np.eye(4)
    tcp[2, 3] = 0.1
    for got, sent in zip(message.points, line):
        tip = arm.kin.forward(np.array(got.joint_values)) @ tcp
        assert np.allclose(tip[:3, 3], [sent.x, sent.y, sent.z], atol=1e-6)
    # In the device's units, whatever they were loaded in.
    arm.device.SetUnits(settings_pb2.SetUnitsRequest(
        linear_units=types_pb2.LINEAR_UNIT_MILLIMETERS,
        angular_units=types_pb2.ANGULAR_UNIT_DEGREES), timeout=10)
    (message,) = get_path(arm.device, "line")
    assert message.units.angular == types_pb2.ANGULAR_UNIT_DEGREES
    assert message.path.tool_offset.z == pytest.approx(100.0)
    assert np.allclose([p.joint_values for p in message.points],
                       np.degrees([p.joint_values for p in get_path_si]))


def test_get_path_streams_a_long_path_in_chunks(arm):
    # One full chunk and one point past it: a boundary, the header in the first message only,
    # a short last one (2,001 points showed nothing more, at twice the storing time).
    joints = joint_points(1001)
    load(arm.device, "long", joints)
    messages = get_path(arm.device, "long")
    assert [(m.first_point, len(m.points)) for m in messages] == [(0, 1000), (1000, 1)]
    assert messages[0].path.number_of_points == 1001
    assert not any(m.HasField("path") for m in messages[1:])
    got = [p.joint_values for m in messages for p in m.points]
    assert np.allclose(got, [p.joint_values for p in joints])


def test_an_unknown_path_is_not_found_and_an_empty_device_lists_none(arm):
    assert list(arm.device.ListPaths(stored_paths_pb2.ListPathsRequest(), timeout=10).paths) == []
    with pytest.raises(grpc.RpcError) as refused:
        get_path(arm.device, "nowhere")
    assert refused.value.code() is grpc.StatusCode.INVALID_ARGUMENT
    assert error_info(refused.value).reason == "NOT_FOUND"
    assert "nowhere" in refused.value.details()


def test_paths_read_back_after_a_restart_without_a_lock(tmp_path):
    file = str(tmp_path / "paths.sqlite3")
    server = start_server(paths_file=file)
    try:
        from landscape.client import Session
        session = Session(grpc.insecure_channel(server.target), "loader").open()
        session.lock()
        load(stubs(session.channel)[0], "kept", joint_points(4))
        session.close()
    finally:
        server.stop(grace=None)
    again = start_server(paths_file=file)
    try:
        device = stubs(grpc.insecure_channel(again.target))[0]   # no session, no lock
        assert [p.name for p in device.ListPaths(stored_paths_pb2.ListPathsRequest(),
                                                 timeout=10).paths] == ["kept"]
        (message,) = get_path(device, "kept")
        assert [p.tag_name for p in message.points] == ["j0", "", "", ""]
    finally:
        again.stop(grace=None)
