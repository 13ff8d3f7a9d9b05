"""`--clock fast`: the cycle process running cycles back to back. The same server and the same
controller as on the real-time clock, only the deadlines are gone: a program runs to the end
in less wall time than it takes on the arm (bench_lockstep.py measures how much less), and
everything else holds."""
from __future__ import annotations

import contextlib
import math
import threading
import time

import grpc

from landscape.client import Session
from landscape.v1 import (control_pb2, event_service_pb2, motion_pb2, sensing_pb2,
                          state_service_pb2, state_service_pb2_grpc, types_pb2)

from support import spawned_server, stubs, wait_until

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME


def _controller_time(channel) -> float:
    """The controller's own clock (s), from the newest state sample."""
    stream = state_service_pb2_grpc.StateServiceStub(channel).StreamState(
        state_service_pb2.StreamStateRequest(rate_hz=10))
    try:
        return next(m.sample.controller_time for m in stream if m.WhichOneof("message") == "sample")
    finally:
        stream.cancel()


def _load_path(device, points: int) -> None:
    """Path "p": `points` joint tags t0, t1, ... swinging the arm to and fro."""
    tags = [types_pb2.TagStruct(tag_name=f"t{i}", transition_speed=30, joint_values=[
        0.8 * math.sin(i / 2), 0.1, 1.5708, 0.3 * math.cos(i / 2), 1.5708, 0.0])
        for i in range(points)]
    device.PathLoad(iter([motion_pb2.PathLoadRequest(
        header=motion_pb2.PathHeader(path_name="p", frame=JOINT,
                                     motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                     offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA),
        tags=tags)]), timeout=30)


@contextlib.contextmanager
def _active(tmp_path, points: int):
    """A server on the fast clock, locked and active, path "p" of `points` tags loaded:
    (channel, device stub, event stream)."""
    with spawned_server("--clock", "fast", "--paths", str(tmp_path / "paths.sqlite3")) as target, \
            grpc.insecure_channel(target) as channel, Session(channel, "fast") as session:
        device, _, events = stubs(session.channel)
        stream = events.Subscribe(event_service_pb2.SubscribeRequest())
        session.lock()
        device.Activate(control_pb2.ActivateRequest(), timeout=10)
        _load_path(device, points)
        try:
            yield channel, device, stream
        finally:
            stream.cancel()
        device.Deactivate(control_pb2.DeactivateRequest(), timeout=10)


def test_a_path_runs_on_the_fast_clock_and_every_tag_is_reported(tmp_path):
    with _active(tmp_path, 12) as (channel, device, stream):
        simulated, wall = _controller_time(channel), time.monotonic()
        seen = _path_events(device, stream, 3)
        wall = time.monotonic() - wall
        simulated = _controller_time(channel) - simulated
        assert seen[-1][0] == "command_done", seen[-1]
        reached = [tag for event, tag in seen if event == "tag_reached"]
        assert reached == [f"t{i}" for i in range(12)] * 3   # every tag, in order
        # How far ahead of the wall clock it runs is bench_lockstep's figure ("whole stack,
        # fast clock"), not asserted here.
        print(f"{simulated:.1f} s of controller time in {wall:.1f} s of wall time")


def _path_events(device, stream, loops: int) -> list[tuple[str, str]]:
    """(event id, tag name) of every event of a PathMove of path "p", to its end."""
    command = device.PathMove(motion_pb2.PathMoveRequest(path_name="p", number_of_cycles=loops),
                              timeout=30).ret_val.command_id
    seen = []
    for reply in stream:
        event = reply.event
        if event.command.command_id == command:
            seen.append((event.event_id, event.command.tag_name))
            if event.event_id in ("command_done", "command_failed"):
                return seen
    raise AssertionError("the event stream ended")


def test_events_and_samples_are_the_same_whether_anyone_watches_the_rows(tmp_path):
    # Issue 31 item 5: with nobody watching, the cycle process reads no sensor and computes no
    # model torques; clients see no difference: the same events, whole samples when they
    # watch, readings when they ask.
    with _active(tmp_path, 8) as (channel, device, stream):
        unwatched = _path_events(device, stream, 2)
        force = device.GetSensorReading(sensing_pb2.GetSensorReadingRequest(
            sensor_type="force_sensor"), timeout=10).current_data
        assert len(force) == 6 and max(abs(v) for v in force) < 1e-3   # nothing on the flange

        watching = state_service_pb2_grpc.StateServiceStub(channel).StreamState(
            state_service_pb2.StreamStateRequest(rate_hz=25, sensors=["force_sensor"]))
        samples = []

        def read():
            try:
                samples.extend(m.sample for m in watching if m.WhichOneof("message") == "sample")
            except grpc.RpcError as error:   # cancelled below, once the path is done
                assert error.code() == grpc.StatusCode.CANCELLED
        reader = threading.Thread(target=read, daemon=True)
        reader.start()
        wait_until(lambda: samples, timeout=10)   # watching before the path starts
        watched = _path_events(device, stream, 2)
        watching.cancel()
        reader.join(10)
        assert watched == unwatched
        assert [tag for event, tag in watched if event == "tag_reached"] == [
            f"t{i}" for i in range(8)] * 2
        assert len(samples) > 1
        for sample in samples:
            assert len(sample.model_torques) == 6
            assert [s.name for s in sample.sensors] == ["force_sensor"]
            assert all(math.isfinite(v) for v in sample.sensors[0].values)
