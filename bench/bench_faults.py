"""How soon faults are handled (issue 26: the figures the tests no longer assert), beside what
bounds each from below in the same run. Prints figures, no pass/fail.

The device server runs here on the real-time clock, as `make run` has it; each fault is made
--repeat times and its figure is the median and the worst:

- cycle process killed (SIGKILL) -> the device's Error alarm (its pipe closes). Goal 50 ms.
- cycle process hung (SIGSTOP) -> the Error alarm (its feedback stops), beside the silence the
  link waits for (silence_cycles cycles). Goal 200 ms.
- lock holder killed (SIGKILL, a process of its own, active) -> drives off and lock free.
  Goal 1 s.
- lock holder frozen (SIGSTOP) -> drives off and lock free, beside its keep-alive timeout.
- lock holder gone while joint 1 moves at 1 rad/s (session closed) -> at rest, drives off and
  unlocked (the device's own event times). Goal 1 s.
- jog deadman: the last jog request sent -> joint 1 at rest (the cycle's own time stamp),
  beside the deadman timeout plus the braking at full deceleration. Goal: that plus 30 ms.

    .venv/bin/python bench/bench_faults.py [--repeat 5]
"""
from __future__ import annotations

import argparse
import os
import queue
import signal
import statistics
import subprocess
import sys
import time
from pathlib import Path

import grpc
import numpy as np
from common import record

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from support import (HOLDER_SCRIPT, activate, locked_session, stubs,  # noqa: E402
                     wait_until)   # the tests' harness

from landscape.server.app import serve  # noqa: E402
from landscape.server.config import ServerConfig  # noqa: E402
from landscape.server.cycle.feedback import QD, WALL  # noqa: E402
from landscape.server.workcell.jog import DEADMAN_TIMEOUT  # noqa: E402
from landscape.server.device.states import State  # noqa: E402
from landscape.robot.controller import EnableState  # noqa: E402
from landscape.v1 import control_pb2, motion_pb2, sensing_pb2, types_pb2  # noqa: E402

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME


def _alarm(server, code: int, after: float, timeout: float = 10.0):
    """The first alarm `code` stamped after `after` (unix s)."""
    subscription = server.bus.subscribe(after_sequence=0)
    try:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            event = subscription.get(timeout=0.5)
            if (event is not None and event.event_id == "alarm" and event.detail.code == code
                    and event.time >= after):
                return event
        raise TimeoutError(f"no alarm {code}")
    finally:
        subscription.close()


def _reset(server) -> None:
    with grpc.insecure_channel(server.target) as channel:
        stubs(channel)[0].Reset(control_pb2.ResetRequest(), timeout=60)
    wait_until(lambda: server.device.state is State.UNLOCKED, timeout=30)


def cycle_process(server, stop: signal.Signals) -> float:
    """s from the signal to the controller-lost alarm."""
    sent = time.time()
    os.kill(server.link.clock.pid, stop)
    took = _alarm(server, 105, sent).time - sent
    _reset(server)   # the link killed a stopped process before it said it was lost
    return took


def holder_process(server, stop: signal.Signals) -> float:
    """s from the signal to the holder's process to drives off and the lock free."""
    child = subprocess.Popen([sys.executable, "-c", HOLDER_SCRIPT, server.target],
                             stdout=subprocess.PIPE, text=True)
    try:
        assert child.stdout.readline().strip() == "active"
        sent = time.monotonic()
        os.kill(child.pid, stop)
        wait_until(lambda: server.device.state is State.UNLOCKED and
                   server.device.feedback().enable is EnableState.DISABLED,
                   timeout=30, period=0.001)
        return time.monotonic() - sent
    finally:
        child.kill()
        if stop == signal.SIGSTOP:
            os.kill(child.pid, signal.SIGCONT)
        child.wait(10)


def holder_gone_moving(server) -> float:
    """s from the holder-lost alarm to unlocked, joint 1 moving at 1 rad/s when it left."""
    session = locked_session(server, "mover")
    device = stubs(session.channel)[0]
    activate(session)
    q = server.device.feedback().position
    device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        frame=JOINT, values=[q[0] + 2.5 if q[0] < 0 else q[0] - 2.5, *q[1:]]), timeout=5)
    wait_until(lambda: abs(server.device.feedback().velocity[0]) > 1.0, timeout=20)
    left = time.time()
    session.close()
    lost = _alarm(server, 101, left)
    wait_until(lambda: server.device.state is State.UNLOCKED, timeout=30, period=0.001)
    subscription = server.bus.subscribe(after_sequence=lost.sequence)
    try:
        while (event := subscription.get(timeout=5)) is not None:
            if event.event_id == "state_changed" and event.detail.to_state == "unlocked":
                return event.time - lost.time
    finally:
        subscription.close()
    raise TimeoutError("no state change to unlocked")


def deadman(server) -> tuple[float, float]:
    """s from the last jog request sent to joint 1 at rest (the cycle's own stamp), and s
    its braking takes at the arm's full deceleration."""
    session = locked_session(server, "pendant")
    device = stubs(session.channel)[0]
    try:
        activate(session)
        device.ManualControl(sensing_pb2.ManualControlRequest(
            type=sensing_pb2.MANUAL_CONTROL_TYPE_TEACHPENDANT), timeout=5)
        requests: queue.Queue = queue.Queue()
        call = device.Jog(iter(requests.get, None), timeout=30)
        sign = -1.0 if server.device.feedback().position[0] > 0 else 1.0
        end = time.monotonic() + 0.5
        while time.monotonic() < end:
            requests.put(sensing_pb2.JogRequest(deadman=True, frame=JOINT,
                                                velocity=[50 * sign, 0, 0, 0, 0, 0]))
            time.sleep(0.02)
        last = time.time()
        ring = server.link.feedback
        first = ring.head
        try:
            for _ in call:
                pass
        except grpc.RpcError:
            pass   # ABORTED by the deadman
        requests.put(None)
        # The stream may end before the jerk-limited braking does: read on until at rest.
        wait_until(lambda: abs(server.device.feedback().velocity[0]) < 1e-6, timeout=5)
        rows = np.array([r for r in (ring.row(s) for s in range(first, ring.head + 1))
                         if r is not None])
        at_rest = rows[(np.abs(rows[:, QD][:, 0]) < 1e-6) & (rows[:, WALL] > last)]
        arm = server.device.arm
        a, j = arm.max_acceleration[0], arm.max_jerk[0]
        braking = np.abs(rows[:, QD][:, 0]).max() / a + a / j   # ramped up and down
        return float(at_rest[0, WALL]) - last, braking
    finally:
        device.ManualControl(sensing_pb2.ManualControlRequest(
            type=sensing_pb2.MANUAL_CONTROL_TYPE_OFF), timeout=5)
        session.close()
        wait_until(lambda: server.device.state is State.UNLOCKED, timeout=30)


def report(what: str, times: list[float], goal: float | None, baseline: float | None = None,
           baseline_name: str = "") -> None:
    ms = [t * 1000 for t in times]
    median, worst = statistics.median(ms), max(ms)
    base = f"   (beside {baseline_name}: {baseline * 1000:.0f} ms)" if baseline else ""
    print(f"{what:<52} median {median:7.1f} ms   worst {worst:7.1f} ms{base}", flush=True)
    record(f"faults: {what}, worst", worst, "ms", goal=None if goal is None else goal * 1000,
           baseline=None if baseline is None else baseline * 1000, baseline_name=baseline_name)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=5)
    args = parser.parse_args()
    n = args.repeat
    server = serve(ServerConfig(port=0, clock="realtime"))
    try:
        link, sessions = server.link, server.device.sessions
        silence = link.silence_cycles * link.cycle_time
        report("cycle process killed -> Error alarm",
               [cycle_process(server, signal.SIGKILL) for _ in range(n)], 0.05)
        report("cycle process hung -> Error alarm",
               [cycle_process(server, signal.SIGSTOP) for _ in range(n)], 0.2, silence,
               "its silence limit")
        report("lock holder killed -> drives off, lock free",
               [holder_process(server, signal.SIGKILL) for _ in range(n)], 1.0)
        report("lock holder frozen -> drives off, lock free",
               [holder_process(server, signal.SIGSTOP) for _ in range(n)], None,
               sessions.keepalive_timeout, "keep-alive timeout")
        report("lock holder gone moving -> at rest, off, unlocked",
               [holder_gone_moving(server) for _ in range(n)], 1.0)
        runs = [deadman(server) for _ in range(n)]
        bound = DEADMAN_TIMEOUT + max(braking for _, braking in runs)
        report("jog deadman: last request -> at rest", [took for took, _ in runs],
               bound + 0.03, bound, "timeout + braking")
    finally:
        server.stop(grace=None)


if __name__ == "__main__":
    main()
