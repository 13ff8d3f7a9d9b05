"""Memory (issue 17): the device server's resident memory idle, under load, and whether it grows
over a long run. Prints figures, no pass/fail.

The server runs as users start it (`python -m landscape.server`, real-time clock, audit log on),
in a process of its own; its resident memory (VmRSS), its cycle process's and its planning
process's are read from /proc once a second. After a settled idle phase, the load is what a
busy cell puts on it, each part in a child process: the lock holder running a 20-point
blended path again and again (its PathMove commands, tag events and done events; it first
fills the server's bounded event history with operator messages, so that filling it is not
taken for growth), 8 clients calling GetRobotPosition and GetDeviceState back to back, 8
StreamState watchers at 50 Hz and 4 event subscribers.

Growth is the slope of a least-squares line through the samples after the warm-up (the first
quarter of the load phase, at least 10 s: caches, pools and the ring fill), in MB per minute;
a leak of one small object per call shows up there (8 readers make about 5,000 calls a second).

    .venv/bin/python bench/bench_soak.py              # 60 s of load
    .venv/bin/python bench/bench_soak.py --soak       # 10 minutes of load
    .venv/bin/python bench/bench_soak.py --seconds 20 # any length (CI: 20 s)
"""
from __future__ import annotations

import argparse
import asyncio
import math
import os
import multiprocessing as mp
import subprocess
import sys
import tempfile
import threading
import time
from queue import Empty

import grpc
import numpy as np
from common import in_child, record

from landscape.client import AsyncSession
from landscape.server.events.bus import DEFAULT_HISTORY
from landscape.server.planning.process import PROCESS_NAME
from landscape.v1 import (control_pb2, device_service_pb2_grpc, event_service_pb2,
                          event_service_pb2_grpc, motion_pb2, settings_pb2, state_service_pb2,
                          state_service_pb2_grpc, types_pb2)

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
GOAL_GROWTH = 1.0   # MB per minute under steady load: allocator noise, not a leak


def rss_mb(pid: int) -> float:
    with open(f"/proc/{pid}/status") as status:
        kb = next(int(line.split()[1]) for line in status if line.startswith("VmRSS"))
    return kb / 1024


def children(pid: int) -> tuple[int | None, int | None]:
    """The device server's planning process (named so) and its cycle process (the largest of
    the other children: the rest are multiprocessing's helpers), as (cycle, planning)."""
    pids = []   # children are started from a thread of their own (sim/lifeline.py)
    for task in os.listdir(f"/proc/{pid}/task"):
        with open(f"/proc/{pid}/task/{task}/children") as listed:
            pids += [int(c) for c in listed.read().split()]
    planning = [p for p in pids if _comm(p) == PROCESS_NAME]
    cycle = max((p for p in pids if p not in planning), key=rss_mb, default=None)
    return cycle, planning[0] if planning else None


def _comm(pid: int) -> str:
    with open(f"/proc/{pid}/comm") as comm:
        return comm.read().strip()


# -- the load, each part in a child ----------------------------------------------------------

def local(stop) -> threading.Event:
    """A local copy of the manager's event `stop` (asking the manager costs a round trip)."""
    flag = threading.Event()
    threading.Thread(target=lambda: (stop.wait(), flag.set()), daemon=True).start()
    return flag


class SessionLost(Exception):
    """The device ended the holder's session (it found the device unlocked)."""


async def holder(target: str, stop, ready):
    """Lock, activate, load a blended path, run it until `stop` is set; returns runs done.
    A session the device ends (a shared machine starved its keep-alives) is opened again and
    the lock taken again, as a user would: the soak goes on measuring memory."""
    stop, runs, first = local(stop), 0, True
    async with grpc.aio.insecure_channel(target) as channel:
        while not stop.is_set():
            async with AsyncSession(channel, "soak-holder") as session:
                try:
                    runs += await run_paths(channel, session, stop, ready, first)
                except (grpc.aio.AioRpcError, SessionLost) as error:
                    if isinstance(error, grpc.aio.AioRpcError) and \
                            error.code() is not grpc.StatusCode.PERMISSION_DENIED:
                        raise
                    why = error.details() if isinstance(error, grpc.aio.AioRpcError) else error
                    print(f"soak: {why}: a new session", flush=True)
                    await unlocked(channel)
                first = False
    return runs


async def unlocked(channel, timeout: float = 60.0) -> None:
    """Until the device has ended the lost session (its disconnect handler stops the arm and
    frees the lock): a Lock before that is refused."""
    device = device_service_pb2_grpc.DeviceServiceStub(channel)
    end = time.monotonic() + timeout
    while (await device.GetDeviceState(control_pb2.GetDeviceStateRequest())).locked \
            and time.monotonic() < end:
        await asyncio.sleep(0.1)


async def run_paths(channel, session, stop, ready, first: bool) -> int:
    """The holder's work in one session (`first`: load the path and fill the history)."""
    await session.lock()
    md = session.metadata()
    device = device_service_pb2_grpc.DeviceServiceStub(channel)
    events = event_service_pb2_grpc.EventServiceStub(channel).Subscribe(
        event_service_pb2.SubscribeRequest())
    await device.Activate(control_pb2.ActivateRequest(), metadata=md)
    if first:
        await load_path(channel, device, md)
        ready.set()
    runs = 0
    try:
        while not stop.is_set():
            try:
                command = (await device.PathMove(motion_pb2.PathMoveRequest(
                    path_name="soak", number_of_cycles=1), metadata=md)).ret_val.command_id
            except grpc.aio.AioRpcError as error:
                if error.code() is not grpc.StatusCode.FAILED_PRECONDITION:
                    raise
                state = (await device.GetDeviceState(control_pb2.GetDeviceStateRequest())).state
                if state == types_pb2.DEVICE_STATE_UNLOCKED:   # the device ended the session
                    raise SessionLost(error.details()) from None
                if state != types_pb2.DEVICE_STATE_ERROR:
                    raise
                # In error (a shared machine starved the cycle process: the watchdog took it
                # for hung): what a user would do, so that the soak goes on measuring memory.
                print(f"soak: {error.details()}: reset", flush=True)
                await device.Reset(control_pb2.ResetRequest(), metadata=md)
                await device.Activate(control_pb2.ActivateRequest(), metadata=md)
                continue
            async for reply in events:
                if reply.event.command.command_id == command and reply.event.event_id in (
                        "command_done", "command_failed", "command_aborted"):
                    break
            runs += 1
        await device.Deactivate(control_pb2.DeactivateRequest(), metadata=md)
    finally:
        events.cancel()
    return runs


async def load_path(channel, device, md) -> None:
    """The soak's 20-point blended path, and the event history filled (bounded: the last
    DEFAULT_HISTORY events are kept for resuming subscribers, so that what it takes is not
    counted as growth)."""
    await device.SetSpeed(settings_pb2.SetSpeedRequest(
        speed=60, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED), metadata=md)
    points = [types_pb2.TagStruct(
        tag_name=f"t{i}", transition_speed=40,
        joint_values=[0.8 * math.sin(i / 3), 0.2 * math.sin(i / 2), 1.5708,
                      0.4 * math.cos(i / 3), 1.5708, math.sin(i / 4)]) for i in range(20)]
    header = motion_pb2.PathHeader(path_name="soak", frame=JOINT,
                                   motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                   offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)
    await device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header, tags=points)]),
                          metadata=md)
    poster = event_service_pb2_grpc.EventServiceStub(channel)
    while (await poster.PostMessage(event_service_pb2.PostMessageRequest(
            text="soak: filling the event history " + "x" * 40),
            metadata=md)).sequence <= DEFAULT_HISTORY:
        pass


async def readers(target: str, n: int, stop):
    """n callers of GetRobotPosition and GetDeviceState until `stop`; returns calls made."""
    stop = local(stop)
    async with grpc.aio.insecure_channel(target) as channel:
        device = device_service_pb2_grpc.DeviceServiceStub(channel)
        calls = 0

        async def one():
            nonlocal calls
            while not stop.is_set():
                await device.GetRobotPosition(settings_pb2.GetRobotPositionRequest())
                await device.GetDeviceState(control_pb2.GetDeviceStateRequest())
                calls += 2
        await asyncio.gather(*(one() for _ in range(n)))
        return calls


async def watchers(target: str, states: int, subscribers: int, stop):
    """State watchers at 50 Hz and event subscribers until `stop`; returns messages read."""
    async with grpc.aio.insecure_channel(target) as channel:
        state = state_service_pb2_grpc.StateServiceStub(channel)
        event = event_service_pb2_grpc.EventServiceStub(channel)
        calls = [state.StreamState(state_service_pb2.StreamStateRequest(rate_hz=50))
                 for _ in range(states)]
        calls += [event.Subscribe(event_service_pb2.SubscribeRequest())
                  for _ in range(subscribers)]
        got = 0

        async def drain(call):
            nonlocal got
            async for _ in call:
                got += 1
        tasks = [asyncio.ensure_future(drain(call)) for call in calls]
        await asyncio.get_running_loop().run_in_executor(None, stop.wait)
        for call in calls:
            call.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        return got


# -- the run --------------------------------------------------------------------------------------

def start_server(folder: str) -> tuple[subprocess.Popen, str]:
    proc = subprocess.Popen(
        [sys.executable, "-m", "landscape.server", "--port", "0", "--rate-limit", "0",
         "--paths", f"{folder}/paths.sqlite3", "--audit-log", f"{folder}/audit.log"],
        stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    for line in proc.stdout:
        if "listening on" in line:
            return proc, line.rsplit(" ", 1)[-1].strip()
    raise RuntimeError("the device server did not start")


def sample(pids: list, seconds: float, rows: list) -> None:
    """(t, MB of each of `pids`: the server, its cycle and planning processes) once a second
    for `seconds`, and a line a minute. A child gone (a cycle process restarted by a Reset)
    or not yet started is NaN that second, and found again."""
    began, said = time.monotonic(), 0.0
    while (now := time.monotonic() - began) < seconds:
        if None in pids:   # not started yet (the planning process starts with the first plan)
            pids[1:] = children(pids[0])
        row = [now]
        for p in pids:
            try:
                row.append(rss_mb(p) if p else math.nan)
            except FileNotFoundError:
                row.append(math.nan)
                pids[1:] = children(pids[0])
        rows.append(tuple(row))
        if now - said >= 60:
            said = now
            print(f"  {now:5.0f} s: " + ", ".join(f"{m:.1f}" for m in row[1:]) + " MB",
                  flush=True)
        time.sleep(1.0)


def outcome(proc, queue) -> str:
    """What a load child did (its count), or that it failed (its error is printed above): the
    memory figures stand either way."""
    try:
        return f"{queue.get(timeout=120 if proc.is_alive() else 5):,}"
    except Empty:
        return f"(failed: exit code {proc.exitcode})"


def growth(rows: list) -> tuple[float, ...]:
    """MB per minute of each process sampled (least squares, over the seconds it was read)."""
    t = np.array([r[0] for r in rows])
    slopes = []
    for k in range(1, len(rows[0])):
        mb = np.array([r[k] for r in rows])
        read = np.isfinite(mb)
        slopes.append(float(np.polyfit(t[read], mb[read], 1)[0]) * 60 if read.sum() > 1
                      else math.nan)
    return tuple(slopes)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="length of the load phase")
    parser.add_argument("--soak", action="store_true", help="10 minutes of load")
    args = parser.parse_args()
    seconds = 600.0 if args.soak else args.seconds
    warm_up = max(10.0, seconds / 4)
    with tempfile.TemporaryDirectory() as folder:
        proc, target = start_server(folder)
        try:
            time.sleep(3.0)   # the controller enabled, homed, the server settled
            pids = [proc.pid, *children(proc.pid)]
            idle: list = []
            sample(pids, 5.0, idle)
            manager = mp.get_context("spawn").Manager()
            stop, ready = manager.Event(), manager.Event()
            loads = [in_child(holder, target, stop, ready)]
            if not ready.wait(120):
                raise RuntimeError("the lock holder did not get going (its error is above)")
            loads += [in_child(readers, target, 8, stop), in_child(watchers, target, 8, 4, stop)]
            time.sleep(warm_up)
            loaded: list = []
            sample(pids, seconds - warm_up, loaded)
            stop.set()
            runs, calls, messages = (outcome(proc, queue) for proc, queue in loads)
        finally:
            proc.terminate()
            proc.wait(timeout=30)
    (server_idle, cycle_idle, planning_idle), (server_load, cycle_load, planning_load) = (
        [float(np.nanmedian([r[k] for r in rows])) for k in (1, 2, 3)] for rows in (idle, loaded))
    server_growth, cycle_growth, planning_growth = growth(loaded)
    print(f"resident memory (MB), {seconds:g} s of load after {warm_up:g} s of warm-up: "
          f"{runs} path runs, {calls} read calls, {messages} streamed messages")
    for name, at_idle, at_load, grew in (
            ("device server", server_idle, server_load, server_growth),
            ("cycle process", cycle_idle, cycle_load, cycle_growth),
            ("planning process", planning_idle, planning_load, planning_growth)):
        print(f"  {name:17s} idle {at_idle:6.1f}   under load {at_load:6.1f}   "
              f"growth {grew:+6.2f} MB/min")
    print(f"  goal (issue 17): no growth (at most {GOAL_GROWTH:g} MB/min of allocator noise)")
    record("server memory, idle", server_idle, "MB")
    record("server memory, under load", server_load, "MB", baseline=server_idle,
           baseline_name="idle")
    record(f"server memory growth, {seconds:g} s of load", server_growth, "MB/min",
           goal=GOAL_GROWTH)
    record(f"cycle process memory growth, {seconds:g} s of load", cycle_growth, "MB/min",
           goal=GOAL_GROWTH)
    record(f"planning process memory growth, {seconds:g} s of load", planning_growth,
           "MB/min", goal=GOAL_GROWTH)
    record("memory over time (server, cycle process, planning process)", server_load, "MB",
           points=[list(r) for r in idle + [(warm_up + 5.0 + r[0], *r[1:]) for r in loaded]])


if __name__ == "__main__":
    main()
