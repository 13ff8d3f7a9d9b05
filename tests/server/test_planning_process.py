"""Issue 8.2: long paths are planned beside a cycle process in a process of their own, so that
a stop arriving meanwhile finds the server's interpreter free. The planning process plans what
the server would (the same path, the same refusals), follows the cell's collision scene, and
a planning process that dies fails its job and is replaced. Stop latency itself is measured
in bench/bench_stop.py."""
from __future__ import annotations

import math
import os
import signal
import time

import grpc
import numpy as np
import pytest

from landscape.server.app import serve
from landscape.server.planning.collision import CollisionScene
from landscape.server.config import ServerConfig
from landscape.server.api.convert import point_specs
from landscape.server.errors import Collision, Internal, ParamError
from landscape.server.planning.moves import Planner
from landscape.server.planning.process import InProcessPlanning, PlanningProcess, StreamRef
from landscape.server.device.motion_settings import MotionSettings, Units
from landscape.server.planning.targets import Frame
from landscape.robot.cell import load_cell
from landscape.robot.kinematics import Kinematics
from landscape.v1 import motion_pb2, types_pb2

from support import locked_session, stubs

CYCLE = 0.004
HOME = np.array([0.0, 0.0, math.pi / 2, 0.0, math.pi / 2, 0.0])


def _ring(n: int, z: float = 0.6) -> list:
    """n Cartesian points on a ring in front of the arm (m, rad), as PathLoad would parse them."""
    tags = [types_pb2.TagStruct(x=0.5 + 0.1 * math.cos(i / 50), y=0.1 * math.sin(i / 50), z=z,
                                roll=math.pi) for i in range(n)]
    return point_specs(tags, Frame.BASE, Units())


@pytest.fixture(scope="module")
def cell():
    return load_cell(None)


@pytest.fixture
def both(cell):
    """The same jobs in this process and in a planning process, each with its own scene."""
    scene = CollisionScene(cell)
    here = InProcessPlanning(Planner(Kinematics(cell.arm), CYCLE), CollisionScene(cell))
    there = PlanningProcess(scene, CYCLE)
    yield here, there, scene
    there.close()


def _load(planning, specs, name="ring"):
    settings = MotionSettings(load_cell(None).arm)
    path, loaded = planning.run("load_path", None, name, Frame.BASE, False, False, specs,
                                settings, set(), HOME, None)
    assert loaded == len(specs) if isinstance(specs, list) else loaded > 0
    return path


def test_the_planning_process_plans_what_the_server_would(both):
    here, there, _ = both
    specs = _ring(200)
    local, remote = _load(here, specs), _load(there, specs)
    assert remote == local
    settings = MotionSettings(load_cell(None).arm)
    run_here = here.run("plan_path_run", local, HOME, settings, 2, "PathMove ring")
    run_there = there.run("plan_path_run", remote, HOME, settings, 2, "PathMove ring")
    assert len(run_there) == len(run_here)
    for a, b in zip(run_here, run_there):
        np.testing.assert_array_equal(a.positions, b.positions)
        assert a.marks == b.marks


def _messages(n: int, per_message: int = 100) -> list:
    header = motion_pb2.PathHeader(path_name="ring",
                                   frame=types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME,
                                   motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                   offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)
    tags = [types_pb2.TagStruct(x=0.5 + 0.1 * math.cos(i / 50), y=0.1 * math.sin(i / 50),
                                z=0.6, roll=math.pi, tag_name=f"t{i}") for i in range(n)]
    return [motion_pb2.PathLoadRequest(header=header)] + [
        motion_pb2.PathLoadRequest(tags=tags[i:i + per_message])
        for i in range(0, n, per_message)]


def _stream(planning, messages) -> str:
    key = planning.open_stream(Units())
    for message in messages:
        planning.feed_stream(key, message)
    return key


def test_a_path_load_stream_is_kept_and_loaded_where_it_is_planned(both):
    here, there, _ = both
    paths = []
    for planning in (here, there):
        key = _stream(planning, _messages(250))
        header, frame = planning.run("finish_stream", key)
        assert header.path_name == "ring" and frame is Frame.BASE
        paths.append(_load(planning, StreamRef(key)))
        planning.drop_stream(key)
        with pytest.raises(Internal, match="lost"):   # dropped: nothing is kept
            _load(planning, StreamRef(key))
    assert paths[0] == paths[1] and len(paths[0].points) == 250
    assert [p.tag_name for p in paths[1].points[:2]] == ["t0", "t1"]
    # A message refused in the planning process is refused as the server would refuse it.
    bad = _messages(10)
    bad[1].tags[3].x = math.nan
    refusals = []
    for planning in (here, there):
        with pytest.raises(ParamError) as refused:
            _stream(planning, bad)
        refusals.append((refused.value.message, refused.value.metadata))
    assert refusals[0] == refusals[1] and refusals[0][1]["index"] == "3"


def test_a_refusal_comes_back_as_the_server_would_raise_it(both):
    here, there, _ = both
    into_the_table = _ring(10) + _ring(10, z=0.15)   # the table's top is at 0.2 m
    with pytest.raises(Exception) as local:
        _load(here, into_the_table)
    with pytest.raises(type(local.value)) as remote:
        _load(there, into_the_table)
    assert remote.value.message == local.value.message
    assert remote.value.metadata == local.value.metadata


def test_the_planning_process_follows_the_scene(both, cell):
    _, there, scene = both
    specs = _ring(160)
    _load(there, specs)                      # clear as the cell is
    # A part put down on the ring's way (its point 150, 0.2 m from its start), in the server's
    # scene: the next job knows it.
    on_the_way = np.eye(4)
    on_the_way[:3, 3] = [0.5 + 0.1 * math.cos(3.0), 0.1 * math.sin(3.0), 0.6]
    scene.place_part(cell.world.parts[0].name, on_the_way)
    with pytest.raises(Collision) as refused:
        _load(there, specs)
    assert cell.world.parts[0].name in refused.value.message


def test_a_planning_process_that_dies_fails_its_job_and_is_replaced(both):
    _, there, _ = both
    lost = []
    there.on_lost = lost.append   # the device raises its alarm there
    first = there.pid
    key = _stream(there, _messages(10))
    os.kill(there.pid, signal.SIGKILL)
    with pytest.raises(Internal, match="planning process ended"):
        _load(there, _ring(5))
    assert there.pid != first
    assert len(lost) == 1 and "another one has started" in lost[0]
    assert len(_load(there, _ring(5)).points) == 5
    with pytest.raises(Internal, match="lost with the planning process"):   # its stream
        there.feed_stream(key, _messages(20, per_message=10)[2])


def _threads(pid: int) -> dict[int, tuple[int, int]]:
    """A process's threads: thread id -> (niceness, ns on a CPU so far)."""
    out = {}
    for tid in os.listdir(f"/proc/{pid}/task"):
        fields = open(f"/proc/{pid}/task/{tid}/stat").read().rsplit(") ", 1)[1].split()
        ns = int(open(f"/proc/{pid}/task/{tid}/schedstat").read().split()[0])
        out[int(tid)] = (int(fields[16]), ns)
    return out


def test_the_planning_process_yields_the_cpu_to_the_server_except_for_a_start(both):
    """Background work (loads, the stretches timed ahead of a moving arm) runs at niceness +10:
    on a busy machine the server's threads (a stop on its way to the cycle) run first. A run's
    start, which a client waits for with the arm at rest, runs at the server's niceness (issue
    31 item 4: at +10 a core busy with other work held a 100-point path's start 10 to 140 ms).
    Before, the whole process ran at +10."""
    _, there, _ = both
    path = _load(there, _ring(200))   # a background job: the process is up
    own = os.getpriority(os.PRIO_PROCESS, 0)
    before = _threads(there.pid)
    assert before[there.pid][0] == own   # its main thread, which takes the jobs
    assert min(own + 10, 19) in [nice for nice, _ in before.values()]
    settings = MotionSettings(load_cell(None).arm)
    for run in range(3):
        there.run("plan_path_lazily", f"run-{run}", path, HOME, settings, 1, "start", 20.0)
    after = _threads(there.pid)
    worked = {tid: after[tid][1] - ns for tid, (_, ns) in before.items() if tid in after}
    assert max(worked, key=worked.get) == there.pid, worked   # the start ran at own niceness


def _cpu_seconds(pid: int) -> float:
    fields = open(f"/proc/{pid}/stat").read().rsplit(") ", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def test_a_long_path_is_planned_outside_the_servers_interpreter():
    """Before: the server's own threads did the work, and a stop's handler waited for them."""
    server = serve(ServerConfig(port=0, clock="realtime"))
    holder = locked_session(server)
    try:
        device, _, _ = stubs(holder.channel)
        planning = server.device.path_runs.planning
        assert isinstance(planning, PlanningProcess) and planning.pid != os.getpid()
        tags = [types_pb2.TagStruct(x=0.5 + 0.1 * math.cos(i / 300), y=0.1 * math.sin(i / 300),
                                    z=0.6, roll=math.pi) for i in range(2000)]
        header = motion_pb2.PathHeader(path_name="long",
                                       frame=types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME,
                                       motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                       offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)
        server_before, planning_before = time.process_time(), _cpu_seconds(planning.pid)
        reply = device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header, tags=tags)]),
                                timeout=120)
        server_cpu = time.process_time() - server_before
        planning_cpu = _cpu_seconds(planning.pid) - planning_before
        print(f"2,000-point path: planning process {planning_cpu:.2f} s of CPU, "
              f"server {server_cpu:.2f} s")
        assert reply.points_loaded == 2000
        assert planning_cpu > 2 * server_cpu
        # The messages reach the planning process as the bytes they came in: bytes that are no
        # PathLoadRequest are refused there, and nothing is stored.
        raw = holder.channel.stream_unary("/landscape.v1.DeviceService/PathLoad")
        first = motion_pb2.PathLoadRequest(header=header, tags=tags[:5]).SerializeToString()
        with pytest.raises(grpc.RpcError) as refused:
            raw(iter([first, b"\xff\xff\xff"]), timeout=30,
                metadata=(("landscape-lease", holder.lease),))
        assert refused.value.code() is grpc.StatusCode.INVALID_ARGUMENT
        assert "message 1 of the PathLoad stream" in refused.value.details()
        assert len(server.device.path_runs.paths.get("long").points) == 2000
    finally:
        holder.close()
        server.stop(grace=None)
