"""Issue 12: StateService.StreamState, the device's state cycle by cycle to any number of
watchers, on the real-time clock (250 Hz) and the lock-step one."""
from __future__ import annotations

import itertools
import math
import threading
import time

import grpc
import numpy as np
import pytest

from landscape.server.app import serve
from landscape.server.config import ServerConfig
from landscape.server.link.controller_link import build_controller
from landscape.server.cycle.feedback import FeedbackRing
from landscape.server.cycle.process import Mailbox
from landscape.v1 import (settings_pb2, state_service_pb2, state_service_pb2_grpc, types_pb2)

from support import locked_session, stubs

MM_DEG = types_pb2.Units(linear=types_pb2.LINEAR_UNIT_MILLIMETERS,
                         angular=types_pb2.ANGULAR_UNIT_DEGREES)


@pytest.fixture(scope="module")
def realtime():
    server = serve(ServerConfig(port=0, clock="realtime"))
    yield server
    server.stop(grace=None)


def _stream(channel, **request):
    stub = state_service_pb2_grpc.StateServiceStub(channel)
    call = stub.StreamState(state_service_pb2.StreamStateRequest(**request), timeout=60)
    started = next(call).started
    return call, started


def _samples(call, n):
    return [next(call).sample for _ in range(n)]


def test_watchers_that_come_after_the_others_left_get_the_arm_as_it_is_now(realtime):
    """The hub listens to the cycles only while someone watches (issue 31 item 5): a watcher
    after a quiet spell (the cycles' wake-ups pile up unheard meanwhile) gets consecutive
    samples of the newest cycles, as the first one did."""
    for _ in range(3):
        with grpc.insecure_channel(realtime.target) as channel:
            call, _ = _stream(channel)
            samples = _samples(call, 20)
            call.cancel()
        sequences = [s.sequence for s in samples]
        assert sequences[0] >= realtime.link.feedback.head - 250     # not a stale one
        assert all(s.skipped == 0 for s in samples[1:])
        assert len(set(sequences)) == 20 and sequences == sorted(sequences)
        time.sleep(0.5)                                                # nobody watches


def test_every_cycle_reaches_a_reader_with_no_gap(realtime):
    with grpc.insecure_channel(realtime.target) as channel:
        call, started = _stream(channel)
        assert started.granted_rate_hz == pytest.approx(250) and started.note == ""
        samples = _samples(call, 500)
        call.cancel()
    sequences = np.array([s.sequence for s in samples])
    assert np.all(np.diff(sequences) == 1), np.unique(np.diff(sequences))
    assert all(s.skipped == 0 for s in samples)
    times = np.array([s.controller_time for s in samples])
    assert np.allclose(np.diff(times), 0.004)


def test_a_stalled_reader_is_thinned_and_slows_nobody(realtime):
    # What a stalled reader finds waiting in the transport is its own HTTP/2 window (grpc
    # grows it by probing unless told not to); beyond that the server thins it.
    small_window = [("grpc.use_local_subchannel_pool", 1), ("grpc.http2.bdp_probe", 0),
                    ("grpc.http2.lookahead_bytes", 16384)]
    with grpc.insecure_channel(realtime.target) as channel, \
            grpc.insecure_channel(realtime.target, options=small_window) as other:
        stalled, _ = _stream(other)
        next(stalled)
        before = realtime.link.stats()
        reader, _ = _stream(channel)
        got = _samples(reader, 750)   # 3 s while the other reads nothing
        after = realtime.link.stats()
        # Up to its first thinned sample (not all 2000: they took 8 s more at 250 Hz).
        late = list(itertools.islice(
            (s for s in (next(stalled).sample for _ in range(2000)) if s.skipped), 1))
        reader.cancel()
        stalled.cancel()
    steps = np.diff([s.sequence for s in got])
    assert np.all(steps == 1), (np.unique(steps), [s.skipped for s in got if s.skipped])
    assert late, "the stalled reader was never thinned"
    # The cycle's deadlines are timing, measured in bench_state beside 50 readers: a shared
    # machine can make any cycle late, whoever reads (printed here, not asserted).
    print(f"the stalled reader skipped {late[0].skipped} cycles to the newest; cycles missed "
          f"meanwhile: {after.missed - before.missed}")


def test_rates_are_granted_or_explained(realtime):
    with grpc.insecure_channel(realtime.target) as channel:
        call, started = _stream(channel, rate_hz=50)
        assert started.granted_rate_hz == pytest.approx(50) and started.note == ""
        sequences = [s.sequence for s in _samples(call, 20)]
        assert set(np.diff(sequences)) == {5}
        call.cancel()
        call, started = _stream(channel, rate_hz=1000)
        assert started.granted_rate_hz == pytest.approx(250) and "cycle rate" in started.note
        call.cancel()
        call, started = _stream(channel, rate_hz=33)
        assert started.granted_rate_hz == pytest.approx(31.25) and "every 8 cycles" in started.note
        call.cancel()


@pytest.mark.parametrize("request_fields", [dict(rate_hz=math.nan), dict(rate_hz=-1),
                                            dict(frame=types_pb2.REFERENCE_FRAME_TOOL_FRAME),
                                            dict(frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME)])
def test_bad_requests_are_refused(server, request_fields):
    with grpc.insecure_channel(server.target) as channel:
        with pytest.raises(grpc.RpcError) as refused:
            _stream(channel, **request_fields)
    assert refused.value.code() is grpc.StatusCode.INVALID_ARGUMENT


def test_units_and_frames_follow_the_request(server):
    holder = locked_session(server)
    try:
        device, _, _ = stubs(holder.channel)
        device.SetWorldCartesianFrame(settings_pb2.SetWorldCartesianFrameRequest(
            frame=types_pb2.Pose(x=0.5, y=-0.2, z=0.1, yaw=0.3)), timeout=5)
        position = device.GetRobotPosition(settings_pb2.GetRobotPositionRequest(), timeout=5)
        with grpc.insecure_channel(server.target) as channel:
            call, started = _stream(channel, units=MM_DEG,
                                    frame=types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME)
            assert started.units == MM_DEG
            base = next(call).sample
            call.cancel()
            call, started = _stream(channel)   # world frame, the device's units (m, rad)
            assert started.frame == types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME
            world = next(call).sample
            call.cancel()
        joints_deg = np.degrees(position.joint_position)
        assert np.allclose(base.joint_positions, joints_deg, atol=1e-6)
        assert base.units == MM_DEG
        w = world.tool_pose
        assert (w.x, w.y, w.z, w.yaw) == pytest.approx(
            (position.world_position.x, position.world_position.y, position.world_position.z,
             position.world_position.yaw), abs=1e-9)
        # Base = world frame (0.5, -0.2, 0.1, yaw 0.3) applied to the world pose, in mm.
        c, s = math.cos(0.3), math.sin(0.3)
        x = 0.5 + c * w.x - s * w.y
        y = -0.2 + s * w.x + c * w.y
        assert (base.tool_pose.x, base.tool_pose.y, base.tool_pose.z) == pytest.approx(
            (1000 * x, 1000 * y, 1000 * (w.z + 0.1)), abs=1e-6)
        turn = (base.tool_pose.yaw - math.degrees(w.yaw + 0.3) + 180) % 360 - 180
        assert turn == pytest.approx(0, abs=1e-6)
    finally:
        holder.close()


def test_many_watchers_share_the_samples(server):
    """Fifty streams on one server, each reading: all get samples, none waits for another."""
    counts = [0] * 50
    with grpc.insecure_channel(server.target) as channel:
        calls = [_stream(channel, rate_hz=50)[0] for _ in range(50)]

        def read(i):
            for _ in range(20):
                next(calls[i])
                counts[i] += 1

        threads = [threading.Thread(target=read, args=(i,)) for i in range(50)]
        began = time.monotonic()
        for thread in threads:
            thread.start()
        for thread in threads:
            thread.join(30)
        for call in calls:
            call.cancel()
    assert counts == [20] * 50, f"in {time.monotonic() - began:.1f} s"


def test_a_motion_ending_while_its_sample_is_made_leaves_the_stream_alone(server, monkeypatch):
    """Found from outside: the running motion can end between two reads of it, and a stream
    whose sample read it twice ended with INTERNAL. Here every read alternates between a
    running motion and none."""
    from landscape.server.device.motion_control import MotionControl, RunningMotion
    reads = itertools.cycle([RunningMotion("PathMove-1", "PathMove", "ring", {}), None])
    monkeypatch.setattr(MotionControl, "running", property(lambda self: next(reads)))
    with grpc.insecure_channel(server.target) as channel:
        call, _ = _stream(channel)
        samples = _samples(call, 6)
        call.cancel()
    assert {s.point_name for s in samples} <= {"ring", ""}


def test_a_cycles_time_stamp_is_its_tick():
    """A sample's time is when its cycle began, as a real controller's cyclic function runs at
    the tick: the simulated one computes its physics first, which took 0.5 to 1.7 ms of every
    cycle into a stop's latency. Before, the row was stamped after the physics."""
    ring = FeedbackRing()
    controller = build_controller(None, ring, Mailbox())
    try:
        for _ in range(3):
            before = time.time()
            controller.step()
            sample = ring.latest()
            assert sample.wall_time == controller.wall_time >= before
    finally:
        controller.destroy()
