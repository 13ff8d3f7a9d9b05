"""Cycle timing benchmark: real-time jitter of the cycle process, and lock-step speed.

    python bench/bench_cycle.py [--seconds 60] [--busy-threads 2] [--lock-step-seconds 60]

Prints figures, decides nothing. Each real-time run lasts --seconds while the parent process
is busy the way the device server would be (Python threads burning CPU, as gRPC handlers and
planning do), and uses the same loop (cycle_process.CycleLoop) with the same statistics:

  process, empty step      the loop alone in its process: the floor this machine allows
  process, TX90 moving     the real BulletController in its cycle process, arm shuttling,
                           the parent asking its state at 50 Hz through the proxy
    same, normal policy    as above without SCHED_FIFO (RealTimeClock(rt_priority=None))
  thread,  TX90 moving     the same loop as a thread of the busy parent: why it is a process

then the lock-step clock's speed with the real arm moving (simulated s per wall s).
Lateness is a cycle's start minus its deadline; an overrun is a cycle late by more than one
period. DESIGN.md section 7 quotes what these figures decided.
"""
from __future__ import annotations

import argparse
import functools
import itertools
import os
import sys
import threading
import time

import numpy as np
from common import record

from landscape.robot.cell import load_cell
from landscape.server.link.clock import LockStepClock, RealTimeClock
from landscape.robot.controller import EnableState
from landscape.server.cycle.process import CycleLoop
from landscape.server.cycle.stats import CycleStats, StatsRing
from landscape.sim.movegen import JointMove

# Joint offsets (rad) from the start pose between which the arm shuttles, and the time per move.
SWING = np.array([0.6, 0.35, -0.4, 0.8, 0.5, 1.0])
MOVE_S = 1.5


class NullController:
    """Empty step: measures the loop and the machine, nothing else."""

    def __init__(self, cycle_time: float):
        self.cycle_time = cycle_time

    def step(self) -> None:
        pass


def null_controller(mailbox, cycle_time: float) -> NullController:
    return NullController(cycle_time)


class Shuttle:
    """Cyclic function: JointMove back and forth between the start pose and start + SWING."""

    def __init__(self, cycle_time: float):
        self.move = JointMove(cycle_time)
        self.targets = None

    def __call__(self, ctrl) -> bool:
        # Moves start once the drives are on (state() is allowed in the cycle, LLI 5.3.1).
        if not self.move.moving and ctrl.state().enable == EnableState.ENABLED:
            if self.targets is None:
                home = ctrl.get().pos.copy()
                self.targets = itertools.cycle((home + SWING, home))
            self.move.start(next(self.targets), MOVE_S)
        return self.move(ctrl)


def shuttling_arm(mailbox=None, cell_path: str | None = None):
    """The default cell's TX90, initialised and enabled, shuttling (built where it runs)."""
    from landscape.sim.bullet_controller import BulletController  # pybullet: only where it runs

    cell = load_cell(cell_path)
    shuttle = Shuttle(cell.controller.cycle_time)
    ctrl = BulletController(cell, shuttle)
    ctrl.init()
    ctrl.enable()
    if not LockStepClock(ctrl).run_until(
            lambda: ctrl.state().enable == EnableState.ENABLED, timeout_s=5.0):
        raise RuntimeError("the arm did not enable")
    return ctrl


class BusyParent:
    """`n` Python threads burning CPU in this process, as the server's gRPC work would."""

    def __init__(self, n: int):
        self.n = n
        self._stop = threading.Event()
        self._threads: list[threading.Thread] = []

    def _burn(self) -> None:
        x = 0
        while not self._stop.is_set():
            for i in range(2000):
                x += i * i % 7

    def __enter__(self):
        self._threads = [threading.Thread(target=self._burn, daemon=True) for _ in range(self.n)]
        for t in self._threads:
            t.start()
        return self

    def __exit__(self, *exc):
        self._stop.set()
        for t in self._threads:
            t.join()


def run_process(factory, seconds: float, busy: int, poll_state: bool,
                rt_priority: int | None = 50) -> CycleStats:
    """The factory's controller in a RealTimeClock for `seconds`, the parent busy meanwhile
    and, if `poll_state`, asking the controller's state at 50 Hz as a server would."""
    with RealTimeClock(factory, rt_priority=rt_priority) as clock:
        if clock.tuning_problems:
            print("   (tuning:", "; ".join(clock.tuning_problems) + ")")
        time.sleep(0.5)  # let the first cycles and page faults pass
        clock.reset_stats()
        with BusyParent(busy):
            end = time.monotonic() + seconds
            while time.monotonic() < end:
                if poll_state:
                    clock.proxy.state()
                time.sleep(0.02)
        return clock.stats()


def run_thread(seconds: float, busy: int) -> CycleStats:
    """The same loop and arm as a thread of this (busy) process."""
    ctrl = shuttling_arm()
    stats = StatsRing()
    loop = CycleLoop(ctrl.step, ctrl.cycle_time, stats)
    stop = threading.Event()
    thread = threading.Thread(target=loop.run, args=(lambda _deadline: not stop.is_set(),),
                              daemon=True)
    thread.start()
    try:
        time.sleep(0.5)
        # Resetting from here races one sample at most: fine for a benchmark.
        stats.reset()
        with BusyParent(busy):
            time.sleep(seconds)
    finally:
        stop.set()
        thread.join()
        ctrl.destroy()
    return stats.snapshot(ctrl.cycle_time)


def run_lock_step(sim_seconds: float) -> tuple[float, float]:
    """Wall seconds and cycles per wall second for `sim_seconds` of the shuttling arm."""
    ctrl = shuttling_arm()
    clock = LockStepClock(ctrl)
    started = time.perf_counter()
    cycles = clock.run_for(sim_seconds)
    wall = time.perf_counter() - started
    ctrl.destroy()
    return wall, cycles / wall


def row(name: str, s: CycleStats) -> str:
    ms = lambda x: f"{x * 1e3:7.3f}"  # noqa: E731
    return (f"{name:28s} {s.cycles:7d} {s.overruns:6d} {s.missed:6d} "
            f"{ms(s.period_p50)} {ms(s.period_p99)} {ms(s.period_max)}   "
            f"{ms(s.late_p50)} {ms(s.late_p99)} {ms(s.late_max)}   "
            f"{ms(s.exec_p50)} {ms(s.exec_p99)}")


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--seconds", type=float, default=60.0, help="length of each real-time run")
    parser.add_argument("--busy-threads", type=int, default=2)
    parser.add_argument("--lock-step-seconds", type=float, default=60.0, help="simulated s")
    args = parser.parse_args(argv)
    cycle_time = load_cell().controller.cycle_time

    print(f"machine: {os.cpu_count()} CPUs, Python {sys.version.split()[0]}; cycle "
          f"{cycle_time * 1e3:g} ms; {args.seconds:g} s per real-time run, parent busy with "
          f"{args.busy_threads} CPU-bound threads")
    runs = [
        ("process, empty step", lambda: run_process(
            functools.partial(null_controller, cycle_time=cycle_time),
            args.seconds, args.busy_threads, poll_state=False)),
        ("process, TX90 moving", lambda: run_process(
            shuttling_arm, args.seconds, args.busy_threads, poll_state=True)),
        ("  same, normal policy", lambda: run_process(
            shuttling_arm, args.seconds, args.busy_threads, poll_state=True, rt_priority=None)),
        ("thread in parent, TX90 moving", lambda: run_thread(args.seconds, args.busy_threads)),
    ]
    results = []
    for name, run in runs:
        print(f"-- {name} ...", flush=True)
        results.append((name, run()))
    print()
    print(f"{'real time (ms)':28s} {'cycles':>7s} {'overr':>6s} {'missed':>6s} "
          f"{'period p50':>10s} {'p99':>7s} {'max':>7s}   {'late p50':>7s} {'p99':>7s} "
          f"{'max':>7s}   {'exec p50':>7s} {'p99':>7s}")
    for name, stats in results:
        print(row(name, stats))
        label = name.strip().replace("same, ", "TX90 moving, ")
        record(f"cycle lateness p99, {label}", stats.late_p99 * 1e3, "ms",
               baseline=stats.late_p50 * 1e3, baseline_name="p50")
        record(f"cycle lateness max, {label}", stats.late_max * 1e3, "ms")
        record(f"missed cycles, {label}", stats.missed, "cycles",
               goal=0 if name.startswith("process") else None)

    wall, rate = run_lock_step(args.lock_step_seconds)
    print(f"\nlock step, TX90 moving: {args.lock_step_seconds:g} simulated s in {wall:.2f} wall s "
          f"= {rate:.0f} cycles/s = {args.lock_step_seconds / wall:.1f} simulated s per wall s")


if __name__ == "__main__":
    main()
