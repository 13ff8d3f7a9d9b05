"""The device server's line to its controller, on either clock (DESIGN.md section 7).

- "realtime": the controller and the Executor run in a cycle process of their own, stepped
  every cycle on wall-clock deadlines (landscape.sim.clock.RealTimeClock).
- "lockstep": they run in this process on a thread that steps cycle after cycle as fast as it
  can (landscape.sim.clock.ThreadedLockStepClock): deterministic physics, simulated time far
  ahead of the wall clock. For tests.

Both offer the same surface: `proxy` (the asynchronous LLI calls, served between cycles),
`on_message` (the Executor's posts), `between_cycles` and `stop()`.
"""
from __future__ import annotations

import functools
from typing import Any, Callable

from landscape.server.executor import Executor
from landscape.sim.clock import RealTimeClock, ThreadedLockStepClock
from landscape.sim.cycle_process import Mailbox

CLOCKS = ("realtime", "lockstep")


def build_controller(cell_path: str | None, mailbox: Mailbox):
    """Factory run where the cycle runs: the simulated CS8 with the Executor as cyclic function."""
    from landscape.sim.bullet_controller import BulletController  # pybullet: only here
    from landscape.sim.cell import load_cell
    cell = load_cell(cell_path)
    return BulletController(cell, cyclic=Executor(mailbox, cell.controller.cycle_time))


def open_link(clock: str, cell_path: str | None, on_message: Callable[[Any], None],
              pace: float | None = None):
    """pace: lock-step only, at most this many simulated seconds per wall second (None: as
    fast as possible)."""
    factory = functools.partial(build_controller, cell_path)
    if clock == "realtime":
        return RealTimeClock(factory, on_message=on_message).start()
    if clock == "lockstep":
        return ThreadedLockStepClock(factory, on_message, pace)
    raise ValueError(f"unknown clock {clock!r}; choose one of {', '.join(CLOCKS)}")
