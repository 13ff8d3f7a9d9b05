"""Named paths with tags (seed 3.5): load, append, clear, run with blends, dwells, aux commands,
cycles and dry runs, and their survival across a restart; real server, simulated arm."""
from __future__ import annotations

import math
import pickle

import grpc
import numpy as np
import pytest

from landscape.server.planning.paths import PathPoint, StoredPath
from landscape.server.device.states import State
from landscape.robot.controller import DioStatus
from landscape.v1 import motion_pb2, settings_pb2, types_pb2

from support import Arm, distance_to_line, error_info, start_server, wait_until

JOINT, BASE = types_pb2.REFERENCE_FRAME_JOINT_FRAME, types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME
ABSOLUTE = types_pb2.OFFSET_TYPE_ABSOLUTE_DATA


@pytest.fixture
def arm(tmp_path, backend):
    a = Arm(tmp_path, backend=backend)
    yield a
    a.close()


def header(name, n, frame=BASE, motion=types_pb2.MOTION_TYPE_JOINT_MOTION):
    return motion_pb2.PathHeader(path_name=name, frame=frame, motion_type=motion,
                                 offset_type=ABSOLUTE, number_of_points=n)


def load(device, head, tags, chunk=7):
    """PathLoad, streamed in chunks of `chunk` points."""
    def requests():
        yield motion_pb2.PathLoadRequest(header=head, tags=tags[:chunk])
        for i in range(chunk, len(tags), chunk):
            yield motion_pb2.PathLoadRequest(tags=tags[i:i + chunk])
    return device.PathLoad(requests(), timeout=30)


def ring(n, radius=0.15, z=0.7, **fields):
    """n tagged points on a horizontal circle in front of the arm, tool pointing down."""
    return [types_pb2.TagStruct(x=0.55 + radius * math.cos(2 * math.pi * i / n),
                                y=radius * math.sin(2 * math.pi * i / n), z=z, roll=math.pi,
                                tag_name=f"t{i}", tag_index=i, **fields) for i in range(n)]


def tag_events(events):
    return [e.command.tag_name for e in events if e.event_id == "tag_reached"]


def test_a_20_tag_blended_path_reports_every_tag_in_order_without_stopping(arm):
    tags = ring(20, transition_speed=50)
    reply = load(arm.device, header("ring", 20), tags)
    assert (reply.points_loaded, reply.path_length) == (20, 20)
    arm.record_start()
    started = arm.device.PathMove(motion_pb2.PathMoveRequest(path_name="ring"))
    events = arm.wait_command(started.ret_val.command_id)
    assert events[-1].event_id == "command_done"
    assert tag_events(events) == [f"t{i}" for i in range(20)]
    tips, data = arm.recorded_tips()
    # Between the first and the last tag the tool never stops: it passes the blended tags.
    speed = np.linalg.norm(np.diff(tips, axis=0), axis=1) / 0.004
    at_first = np.argmin(np.linalg.norm(tips - tips_of(arm, tags[0]), axis=1))
    at_rest = np.flatnonzero(speed > 1e-6)[-1]   # the recording goes on after the path ends
    moving = speed[at_first + 5:at_rest - 30]
    print(f"20-tag ring: lowest tool speed between tags {moving.min():.4f} m/s")
    assert moving.min() > 0.01
    check_limits(arm, data)


def tips_of(arm, tag):
    return np.array([tag.x, tag.y, tag.z])


def check_limits(arm, data):
    """Commanded joint velocity and acceleration within the set percent of the limits."""
    settings = arm.server.device.settings
    vel = np.abs(data["cmd_vel"]).max(axis=0)
    acc = np.abs(np.diff(data["cmd_vel"], axis=0) / 0.004).max(axis=0)
    assert np.all(vel <= settings.joint_velocities * (1 + 1e-6)), vel
    assert np.all(acc <= settings.joint_accelerations * (1 + 1e-6)), acc / settings.joint_accelerations


def test_an_unreachable_point_fails_the_load_by_index_and_nothing_is_stored(arm):
    tags = ring(10)
    tags[7].x = 3.0  # far out of reach
    with pytest.raises(grpc.RpcError) as refused:
        load(arm.device, header("bad", 10), tags)
    assert refused.value.code() is grpc.StatusCode.OUT_OF_RANGE
    assert error_info(refused.value).metadata["index"] == "7"
    assert "point 7" in refused.value.details()
    with pytest.raises(grpc.RpcError) as missing:
        arm.device.PathMove(motion_pb2.PathMoveRequest(path_name="bad"))
    assert missing.value.code() is grpc.StatusCode.INVALID_ARGUMENT
    assert error_info(missing.value).reason == "NOT_FOUND"


def test_loads_append_and_clear_deletes(arm):
    assert load(arm.device, header("p", 3), ring(6)[:3]).path_length == 3
    assert load(arm.device, header("p", 3), ring(6)[3:]).path_length == 6
    arm.device.PathClearPath(motion_pb2.PathClearPathRequest(path_name="p"))
    with pytest.raises(grpc.RpcError) as missing:
        arm.device.PathClearPath(motion_pb2.PathClearPathRequest(path_name="p"))
    assert missing.value.code() is grpc.StatusCode.INVALID_ARGUMENT
    assert error_info(missing.value).reason == "NOT_FOUND"


def test_a_wrong_point_count_or_bad_aux_command_is_refused(arm):
    with pytest.raises(grpc.RpcError) as refused:
        load(arm.device, header("n", 5), ring(4))
    assert refused.value.code() is grpc.StatusCode.INVALID_ARGUMENT
    tags = ring(4)
    tags[2].aux_commands.append("dout no_such_output 1")
    with pytest.raises(grpc.RpcError) as refused:
        load(arm.device, header("aux", 4), tags)
    assert refused.value.code() is grpc.StatusCode.INVALID_ARGUMENT
    assert error_info(refused.value).metadata["index"] == "2"


def test_aux_commands_run_at_their_tag_except_in_a_dry_run(arm):
    tags = ring(4, transition_speed=0)
    tags[2].aux_commands.append("dout lamp_green 1")
    load(arm.device, header("lamp", 4), tags)

    def lamp():
        return arm.link.between_cycles(lambda c: c.read_dio(c.get_dout_id("lamp_green")))

    dry = arm.device.PathMove(motion_pb2.PathMoveRequest(path_name="lamp", number_of_cycles=0))
    assert tag_events(arm.wait_command(dry.ret_val.command_id)) == ["t0", "t1", "t2", "t3"]
    assert lamp() is DioStatus.ZERO
    run = arm.device.PathMove(motion_pb2.PathMoveRequest(path_name="lamp", number_of_cycles=2))
    assert tag_events(arm.wait_command(run.ret_val.command_id)) == ["t0", "t1", "t2", "t3"] * 2
    assert lamp() is DioStatus.ONE


def test_a_dwell_holds_the_arm_at_its_tag(arm):
    tags = ring(3, transition_speed=0)
    tags[1].time_delay = 0.5
    load(arm.device, header("dwell", 3), tags)
    arm.record_start()
    run = arm.device.PathMove(motion_pb2.PathMoveRequest(path_name="dwell"))
    arm.wait_command(run.ret_val.command_id)
    tips, _ = arm.recorded_tips()
    near = np.linalg.norm(tips - tips_of(arm, tags[1]), axis=1) < 1e-4
    assert near.sum() * 0.004 >= 0.5


def test_stop_and_resume_a_path_reports_the_remaining_tags(tmp_path):
    arm = Arm(tmp_path, pace=2.0)
    try:
        load(arm.device, header("slow", 6), ring(6, transition_speed=0, speed=20))
        run = arm.device.PathMove(motion_pb2.PathMoveRequest(path_name="slow"))
        wait_until(lambda: arm.server.device.path_runs.last_tag[1] == "t2", timeout=30)
        arm.device.StopMotion(motion_pb2.StopMotionRequest())
        assert arm.server.device.state is State.PAUSED
        arm.device.ResumeMotion(motion_pb2.ResumeMotionRequest())
        events = arm.wait_command(run.ret_val.command_id)
        assert tag_events(events) == [f"t{i}" for i in range(6)]
        assert "command_paused" in [e.event_id for e in events]
    finally:
        arm.close()


def test_paths_survive_a_restart(tmp_path):
    file = str(tmp_path / "paths.sqlite3")
    server = start_server(paths_file=file)
    server.device.path_runs.paths  # loaded (empty) at start
    try:
        arm_points = [np.array([0.2 * i, 0.1, 1.4, 0.0, 1.2, 0.0]) for i in range(4)]
        from landscape.server.planning.path_planning import PointSpec
        from landscape.server.planning.targets import Frame
        server.device.path_runs.path_load("kept", Frame.JOINT, False, False,
                                [PointSpec(q, tag_name=f"k{i}") for i, q in enumerate(arm_points)])
    finally:
        server.stop(grace=None)
    again = start_server(paths_file=file)
    try:
        kept = again.device.path_runs.paths["kept"]
        assert [p.tag_name for p in kept.points] == ["k0", "k1", "k2", "k3"]
        assert np.allclose(kept.points[3].joints, arm_points[3])
    finally:
        again.stop(grace=None)


def test_a_relative_straight_path_draws_its_square_and_get_tag_id_follows(arm):
    start = arm.tip()[:3, 3]
    side = 0.2
    offsets = [(side, 0), (0, side), (-side, 0), (0, -side)]
    tags = [types_pb2.TagStruct(x=dx, y=dy, tag_name=f"c{i}") for i, (dx, dy) in enumerate(offsets)]
    head = motion_pb2.PathHeader(path_name="square", frame=BASE,
                                 motion_type=types_pb2.MOTION_TYPE_STRAIGHT_MOTION,
                                 offset_type=types_pb2.OFFSET_TYPE_RELATIVE_DATA, number_of_points=4)
    load(arm.device, head, tags)
    arm.record_start()
    run = arm.device.PathMove(motion_pb2.PathMoveRequest(path_name="square"))
    assert tag_events(arm.wait_command(run.ret_val.command_id)) == ["c0", "c1", "c2", "c3"]
    tips, _ = arm.recorded_tips()
    corners = start + np.cumsum([[dx, dy, 0] for dx, dy in offsets], axis=0)
    # From the first corner on (the approach to it is a joint move), every recorded tip lies on
    # one of the square's sides.
    first = np.argmax(np.linalg.norm(tips - corners[0], axis=1) < 1e-4)
    off_square = np.min([distance_to_line(tips[first:], a, b)
                         for a, b in zip(corners[:-1], corners[1:])], axis=0)
    assert off_square.max() < 0.5e-3
    assert np.linalg.norm(arm.tip()[:3, 3] - start) < 0.1e-3
    reply = arm.device.GetTagId(settings_pb2.GetTagIdRequest())
    assert (reply.path_name, reply.tag_id) == ("square", "c3")


def test_a_path_crosses_to_the_planning_process_as_columns():
    """Paths go to the planning process and back pickled. As 2,000 PathPoint objects that was
    one C call holding the server's interpreter for 2.6 ms (a stop arriving meanwhile missed
    its cycle); as columns, rebuilt in Python, the same path comes back equal, field types
    included."""
    points = tuple(PathPoint(joints=tuple(i / 7 + j for j in range(6)), tag_name=f"t{i}",
                             tag_index=i, time_delay=0.5 * (i % 3), transition_speed=20.0,
                             speed=1 / 3, accel=50.0,
                             aux_commands=("dout gripper_close 1",) if i % 4 == 0 else ())
                   for i in range(2000))
    path = StoredPath("long", True, tuple(float(v) for v in np.eye(4).flat), points)
    pickled = pickle.dumps(path, protocol=5)
    assert b"PathPoint" not in pickled   # no object per point
    back = pickle.loads(pickled)
    assert back == path
    assert type(back.points[3].joints[0]) is float and type(back.points[3].tag_index) is int
    empty = StoredPath("empty", False, path.tcp)
    assert pickle.loads(pickle.dumps(empty)) == empty
