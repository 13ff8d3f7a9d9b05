"""Motion start (issue 31 item 4): from the client's send to the first moving cycle, read on the
controller's recorder (the feedback ring, one row per 4 ms cycle), beside a bare unary echo's
round trip in the same run. Prints figures, no pass/fail.

- A joint MoveAbsolute (goal: p99 under 10 ms) and a 100-point blended PathMove (goal: p99
  under 20 ms), each started from rest: p50/p99 of send -> first moving cycle (the tick stamp
  of the first row whose setpoint left the rest position) and of send -> the call's return.
- Where the time goes, from stamps the bench takes in the server's process around the
  device's own calls: send -> the device's handler (gRPC, the guard), the handler -> the run
  message sent to the cycle (planning, the collision check, the hand-over), sent -> the tick
  that played it (the cycle's period: up to 4 ms by design).

- A long blended path's timing (100 points, about 20 s of motion), in this process: the first
  chunk of rows time_in_stretches gives out (issue 31 item 4) beside time_path's timing of
  the whole section, same run.
- A long path (WAVY, 240 points, one 9 rad section) run by PathMove, send -> first moving
  cycle, as in service on this clock (PathRuns.time_ahead: checked as it plays; a section
  that short is timed whole, path_planning.LONG_SECTION) beside timed and checked whole
  before it starts, same run; each run stopped and aborted once it moves.

The device server runs here on the real-time clock (its cycle process apart); the client runs
in a child process, and reads the recorder there (a shared-memory ring), so the bench adds no
work to the server's interpreter beyond its stamps. Run:
.venv/bin/python bench/bench_motion_start.py [--quick]
"""
from __future__ import annotations

import argparse
import asyncio
import math
import time

import grpc
import numpy as np
from common import BareServer, collect, in_child, pct, record
from google.protobuf import wrappers_pb2

from landscape.client import AsyncSession
from landscape.server.app import serve
from landscape.server.config import ServerConfig
from landscape.server.cycle.feedback import CMD, WALL
from landscape.v1 import (control_pb2, device_service_pb2_grpc, motion_pb2, types_pb2)

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
HOME = [0.0, 0.0, 1.5708, 0.0, 1.5708, 0.0]
RING = [[0.3 * math.sin(i / 15), 0.2 * math.sin(i / 25), 1.5708 + 0.1 * math.cos(i / 20),
         0.0, 1.5708, 0.0] for i in range(100)]
KINDS = ("joint move", "100-point path")
# A long blended walk: 100 points, 0.3 rad apart, inside the joint ranges (about 20 s).
LONG = np.cumsum(np.vstack([[0.0, 0.3, 1.4, 0.0, 0.9, 0.0],
                            np.random.default_rng(11).normal(0.0, 0.3, (99, 6))]), axis=0)
# A long blended joint path that PathMove runs (tests/server/test_motion_start.py's): 240
# points, one section of about 9 rad of joint path, 5.6 s.
WAVY = [[0.4 * math.sin(i / 9), 0.3 + 0.15 * math.sin(i / 13), 1.4 + 0.1 * math.cos(i / 11),
         0.2 * math.sin(i / 7), 0.9, 0.0] for i in range(240)]
GOALS = {"joint move": 10.0, "100-point path": 20.0}


async def _echo(request, context):
    return request


def first_moving(ring, since: float, timeout: float = 2.0) -> float:
    """The tick stamp (unix s) of the first cycle at or after `since` whose setpoint differs
    from the cycle before it, read on the recorder."""
    end = time.monotonic() + timeout
    seq = ring.head
    while ring.row(seq) is not None and ring.row(seq)[WALL] >= since:
        seq -= 1         # the first row at or after `since` (the ring holds ~4 s)
    before = ring.row(seq)
    while time.monotonic() < end:
        row = ring.row(seq + 1)
        if row is None:
            time.sleep(0.0005)
            continue
        if row[WALL] >= since and np.max(np.abs(row[CMD] - before[CMD])) > 0.0:
            return float(row[WALL])
        before, seq = row, seq + 1
    raise TimeoutError("no moving cycle within the timeout")


async def starter(target: str, echo_target: str, ring, runs: int):
    """The lock holder: per kind, per run, (send, returned, first moving cycle) unix s; and the
    bare echo's round trips (ms), interleaved with the runs."""
    async with grpc.aio.insecure_channel(target) as channel, \
            grpc.aio.insecure_channel(echo_target) as echo_channel, \
            AsyncSession(channel, "bench") as session:
        await session.lock()
        device = device_service_pb2_grpc.DeviceServiceStub(channel)
        echo = echo_channel.unary_unary(
            "/bench.Bare/Echo", request_serializer=wrappers_pb2.UInt64Value.SerializeToString,
            response_deserializer=wrappers_pb2.UInt64Value.FromString)
        md = session.metadata()
        await device.Activate(control_pb2.ActivateRequest(), metadata=md)
        header = motion_pb2.PathHeader(path_name="bench100", frame=JOINT,
                                       motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                       offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)
        try:
            await device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header, tags=[
                types_pb2.TagStruct(joint_values=q, transition_speed=40) for q in RING])]),
                metadata=md)
        except grpc.aio.AioRpcError:
            pass   # loaded by an earlier run (paths are kept)

        async def resting():
            while (await device.GetDeviceState(control_pb2.GetDeviceStateRequest())
                   ).state != types_pb2.DEVICE_STATE_RESTING:
                await asyncio.sleep(0.02)
            await asyncio.sleep(0.1)

        async def timed(call, request):
            began = time.time()
            await call(request, metadata=md)
            returned = time.time()
            return began, returned, first_moving(ring, began)

        out = {kind: [] for kind in KINDS}
        echoes = []
        for i in range(runs):
            await resting()
            goal = list(HOME)
            goal[0] = 0.2 if i % 2 == 0 else -0.2
            out["joint move"].append(await timed(device.MoveAbsolute, motion_pb2.MoveAbsoluteRequest(
                frame=JOINT, values=goal)))
            await resting()
            await device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(frame=JOINT, values=RING[0]),
                                      metadata=md)
            await resting()
            out["100-point path"].append(await timed(device.PathMove, motion_pb2.PathMoveRequest(
                path_name="bench100")))
            for _ in range(20):
                began = time.perf_counter()
                await echo(wrappers_pb2.UInt64Value(value=1))
                echoes.append((time.perf_counter() - began) * 1000)
        await resting()
        await device.Deactivate(control_pb2.DeactivateRequest(), metadata=md)
        return out, echoes


class Stamps:
    """When the device's handler began and when it sent the run to the cycle (unix s), per
    motion started, from wrappers around the device's own calls."""

    def __init__(self, server):
        self.began: list[float] = []
        self.sent: list[float] = []
        motions, runs = server.device.motions, server.device.path_runs
        motions.move = self._entered(motions.move)
        runs.path_move = self._entered(runs.path_move)
        send = motions.link.send

        def stamped(message):
            send(message)
            if isinstance(message, dict) and message.get("op") == "run":
                self.sent.append(time.time())
        motions.link.send = stamped

    def _entered(self, call):
        def wrapper(*args, **kwargs):
            self.began.append(time.time())
            return call(*args, **kwargs)
        return wrapper


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer runs, for CI")
    parser.add_argument("--runs", type=int, help="runs of each kind (default 60, quick 10)")
    args = parser.parse_args()
    runs = args.runs or (10 if args.quick else 60)
    server = serve(ServerConfig(port=0, clock="realtime"))
    bare = BareServer("bench.Bare", {"Echo": grpc.unary_unary_rpc_method_handler(
        _echo, request_deserializer=wrappers_pb2.UInt64Value.FromString,
        response_serializer=wrappers_pb2.UInt64Value.SerializeToString)})
    try:
        stamps = Stamps(server)
        out, echoes = collect(in_child(starter, server.target, bare.target,
                                       server.link.feedback, runs), 900)
    finally:
        bare.stop()
        server.stop(grace=None)
    # The device's stamps in the order of the runs: each run's joint move, then its approach
    # (a joint move, not timed), then its path.
    began = np.reshape(stamps.began, (runs, 3))[:, [0, 2]]
    sent = np.reshape(stamps.sent, (runs, 3))[:, [0, 2]]
    print(f"send -> first moving cycle, {runs} runs each, ms (p50 / p99); baseline, a bare "
          f"unary echo round trip: {pct(echoes, 50):.2f} / {pct(echoes, 99):.2f}")
    for k, kind in enumerate(KINDS):
        rows = np.array(out[kind])
        send, returned, moving = rows[:, 0], rows[:, 1], rows[:, 2]
        first = (moving - send) * 1000
        parts = {"call returns": (returned - send) * 1000,
                 "  send -> handler": (began[:, k] - send) * 1000,
                 "  handler -> run sent": (sent[:, k] - began[:, k]) * 1000,
                 "  run sent -> its tick": (moving - sent[:, k]) * 1000}
        print(f"  {kind:15s}: first moving cycle {pct(first, 50):6.2f} / {pct(first, 99):6.2f}"
              f"   (goal: p99 under {GOALS[kind]:g})")
        for name, values in parts.items():
            print(f"    {name:24s} {pct(values, 50):6.2f} / {pct(values, 99):6.2f}")
        record(f"send to first moving cycle p99, {kind}", pct(first, 99), "ms",
               baseline=pct(echoes, 99), baseline_name="bare unary echo round trip p99",
               goal=GOALS[kind])
        record(f"send to first moving cycle p50, {kind}", pct(first, 50), "ms",
               baseline=pct(echoes, 50), baseline_name="bare unary echo round trip p50")
    long_path_timing(runs)
    long_path_start(runs)


def long_path_start(runs: int) -> None:
    """send -> first moving cycle of the long path's PathMove, timed as it plays and whole."""
    server = serve(ServerConfig(port=0, clock="realtime"))
    try:
        first = {}
        for lazily in (False, True):
            server.device.path_runs.time_ahead = lazily
            first[lazily] = collect(in_child(long_starter, server.target, server.link.feedback,
                                             runs, not first), 900)
    finally:
        server.stop(grace=None)
    print(f"  long path PathMove (240 points, ~5.6 s), send -> first moving cycle, ms "
          f"(p50 / p99): timed as it plays {pct(first[True], 50):.2f} / "
          f"{pct(first[True], 99):.2f}; timed whole first {pct(first[False], 50):.2f} / "
          f"{pct(first[False], 99):.2f}")
    record("long path PathMove: send to first moving cycle p50", pct(first[True], 50), "ms",
           baseline=pct(first[False], 50), baseline_name="the same, timed whole first, p50")


async def long_starter(target: str, ring, runs: int, load: bool) -> list[float]:
    """The lock holder: the long path (WAVY) loaded if `load`, then per run from its first
    point, PathMove's send -> first moving cycle (ms), the run stopped and aborted once it
    moves."""
    async with grpc.aio.insecure_channel(target) as channel, \
            AsyncSession(channel, "bench") as session:
        await session.lock()
        device = device_service_pb2_grpc.DeviceServiceStub(channel)
        md = session.metadata()
        await device.Activate(control_pb2.ActivateRequest(), metadata=md)
        header = motion_pb2.PathHeader(path_name="long", frame=JOINT,
                                       motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                       offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)
        if load:
            await device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header, tags=[
                types_pb2.TagStruct(joint_values=q, transition_speed=60) for q in WAVY])]),
                metadata=md)

        async def resting():
            while (await device.GetDeviceState(control_pb2.GetDeviceStateRequest())
                   ).state != types_pb2.DEVICE_STATE_RESTING:
                await asyncio.sleep(0.02)
            await asyncio.sleep(0.1)

        out = []
        for _ in range(runs):
            await resting()
            await device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(frame=JOINT,
                                                                     values=WAVY[0]),
                                      metadata=md)
            await resting()
            began = time.time()
            await device.PathMove(motion_pb2.PathMoveRequest(path_name="long"), metadata=md)
            out.append((first_moving(ring, began) - began) * 1000)
            await device.StopMotion(motion_pb2.StopMotionRequest(), metadata=md)
            await device.AbortMotion(motion_pb2.AbortMotionRequest(), metadata=md)
        await resting()
        await device.Deactivate(control_pb2.DeactivateRequest(), metadata=md)
        return out


def long_path_timing(runs: int) -> None:
    """ms to time_in_stretches' first chunk against time_path's whole timing, per run."""
    from landscape.robot.arm import arm_model
    from landscape.server.planning.motion.stretch_timing import time_in_stretches
    from landscape.server.planning.motion.timing import time_path
    from landscape.server.planning.motion.trajectory import Limits
    arm = arm_model()
    limits = Limits.scaled(arm, 100, 100)
    W = np.clip(LONG, 0.8 * arm.lower, 0.8 * arm.upper)
    first, whole = [], []
    for _ in range(runs):
        start = time.perf_counter()
        next(time_in_stretches(W, limits, 0.004))
        first.append((time.perf_counter() - start) * 1000)
        start = time.perf_counter()
        time_path(W, limits, 0.004)
        whole.append((time.perf_counter() - start) * 1000)
    print(f"  long path timing (100 points, ~20 s), ms (p50 / p99): first chunk "
          f"{pct(first, 50):.2f} / {pct(first, 99):.2f}; time_path whole {pct(whole, 50):.2f} / "
          f"{pct(whole, 99):.2f}")
    record("long path: first chunk timed p50", pct(first, 50), "ms", baseline=pct(whole, 50),
           baseline_name="time_path of the whole section p50")


if __name__ == "__main__":
    main()
