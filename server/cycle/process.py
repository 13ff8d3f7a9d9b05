"""The cycle process: a controller stepped on absolute deadlines, serving its parent between cycles.

`RealTimeClock` (realtime_clock.py) starts `cycle_child.child_main` in a process of its own
(spawn), so that the server's Python threads never hold a GIL the cycle needs (DESIGN.md
section 7). This module holds what both sides share: the wire protocol, the Mailbox, the call
dispatch, and the cycle loop; cycle_child.py holds the child's own side.

Each cycle: wait for the deadline (sleep, then spin the last `spin` seconds, because a sleep
alone wakes up tens to hundreds of microseconds late), step the controller (physics, then its
cyclic function), send what the cyclic function posted, then read and serve the parent's
requests, in order, for as long as the time budget before the next deadline allows. Calls that
take long (SLOW_CALLS: storing a recording) run on a thread of their own, the LLI's
asynchronous task, and the calls after them wait (except the urgent lane, RUN_URGENT: the
operator panel); the cycle never does.

Wire protocol over one duplex multiprocessing Pipe; every item is a tuple whose first element
is its tag:

  parent -> child   (CALL, call_id, method, args)   an asynchronous LLI call (CONTROLLER_CALLS)
                                                    or one of the cycle process's own
                    (MSG, payload)                  for the cyclic function's Mailbox.poll()
                    (STOP,)                         leave the loop, disable, destroy, exit
  child -> parent   (READY, info)                   once, after the factory built the controller
                    (REPLY, call_id, ok, value)     the result, or the exception if not ok
                    (MSG, payload)                  posted by the cyclic function (Mailbox.post)
                    (EVENT, text)                   from the controller's event function
                    (FATAL, traceback_text)         the factory or a cycle raised; child exits

The child exits when told to, on SIGTERM, and when its parent is gone, with the drives
disabled: the kernel sends it a SIGTERM the moment its parent dies, however it dies
(lifeline.py), the pipe reports EOF once the parent's end is closed, and the parent pid is
checked as well, so no orphan keeps stepping a robot.
"""
from __future__ import annotations

import time
from collections import deque
from typing import Any, Callable, Protocol

from landscape.robot.controller import check_cycle_time  # noqa: F401  (named here too)
from landscape.server.cycle.stats import StatsRing

CALL, MSG, STOP, READY, REPLY, EVENT, FATAL = (
    "call", "msg", "stop", "ready", "reply", "event", "fatal")

# The asynchronous LLI calls the parent may make (LLI 5.3.1); get/set belong to the cycle.
CONTROLLER_CALLS = frozenset({
    "init", "home", "enable", "disable", "state", "ioctrl",
    "get_din_id", "get_dout_id", "read_dio", "write_dout",
    "io_map", "read_io_unit", "write_io_unit", "sensor_map", "read_sensor", "tare_sensor",
    "forward_kin", "reverse_kin", "rec_init", "rec_start", "rec_stop", "rec_store",
    "capabilities",
})
# Calls that may take long (they write files): served on the cycle process's asynchronous
# thread. They must be safe while step() runs: rec_store only reads samples already recorded.
SLOW_CALLS = frozenset({"rec_store"})
# Calls the cycle process answers itself. RUN: (func, args) -> func(controller, *args), for
# what the LLI has no call for (the simulator's panel, its sensors); func must pickle.
# RUN_URGENT: the same in a lane of its own, served before the other calls even while a slow
# one runs (the operator panel: a person at the cell never waits for a file being written).
# LATE_IMPORTS: the modules imported since the loop started (none should be: an import on the
# loop thread, such as unpickling a function of a module not yet loaded, costs cycles).
PLUG_EVENT_FUNC, RESET_STATS, SIM_TIME, RUN, RUN_URGENT, LATE_IMPORTS = (
    "plug_event_func", "_reset_stats", "_sim_time", "_run", "_run_urgent", "_late_imports")


class Steppable(Protocol):
    """What a clock drives: `step()` advances one cycle of `cycle_time` seconds."""

    cycle_time: float

    def step(self) -> Any: ...


class Mailbox:
    """The cycle's end of the message channel to the parent; nothing here ever blocks.

    `poll()` returns the oldest message the parent sent, or None. `post(msg)` queues a message
    for the parent; it leaves at the end of this cycle. Nothing posted is ever dropped (reports
    of completions, faults and tags must arrive): if the parent stops reading, the queue grows,
    and passing `high_water` items is said as an event for the parent to alarm on, put first
    (not behind the backlog it is about); said again each time the queue grows past it after
    having drained to half of it.
    """

    def __init__(self, high_water: int = 10_000):
        self.inbox: deque = deque()
        self.outbox: deque = deque()
        self.high_water = high_water
        self._warned = False

    def poll(self) -> Any | None:
        return self.inbox.popleft() if self.inbox else None

    def post(self, msg: Any) -> None:
        self._queue((MSG, msg))

    def event(self, text: str) -> None:
        """An LLI event function: forwards the controller's event text to the parent."""
        self._queue((EVENT, str(text)))

    def _queue(self, item: tuple) -> None:
        self.outbox.append(item)
        waiting = len(self.outbox)
        if waiting > self.high_water and not self._warned:
            self._warned = True
            self.outbox.appendleft((EVENT, f"the cycle's outbox holds over {self.high_water} "
                                           f"reports: the server is not reading them"))
        elif self._warned and waiting <= self.high_water // 2:
            self._warned = False


def serve_call(controller, mailbox: Mailbox, method: str, args: tuple) -> Any:
    """What every clock serves between cycles: an asynchronous LLI call, plugging the event
    function (its events go out through the mailbox), or RUN (func, args): func(controller,
    *args)."""
    if method in CONTROLLER_CALLS:
        return getattr(controller, method)(*args)
    if method == PLUG_EVENT_FUNC:
        (plug,) = args
        return controller.plug_event_func(mailbox.event if plug else None)
    if method in (RUN, RUN_URGENT):
        func, func_args = args
        return func(controller, *func_args)
    raise AttributeError(f"{method!r} is not a call served between cycles")


class CycleLoop:
    """Calls `step()` every `cycle_time` seconds on an absolute deadline grid.

    After each step it calls `between(next_deadline)` (perf_counter seconds); that returns
    False to end the loop. A cycle that starts more than one period late is an overrun: the
    loop skips the deadlines it missed (it does not run cycles back to back to catch up), so
    simulated time falls behind wall time by what was skipped. A step that always takes longer
    than the period leaves no pause between cycles (as the LLI's synchronous task would); under
    SCHED_FIFO the kernel's real-time throttling still leaves other tasks 5 % of that core.
    Used by the cycle process and, for comparison, by the benchmark's thread baseline.
    """

    def __init__(self, step: Callable[[], Any], cycle_time: float, stats: StatsRing,
                 spin: float = 0.0005, free: bool = False):
        self.step = step
        self.cycle_time = check_cycle_time(cycle_time)
        self.stats = stats
        self.spin = min(spin, self.cycle_time / 2)
        self.free = free

    def run(self, between: Callable[[float], bool],
            wait: Callable[[float], None] | None = None) -> None:
        """wait(deadline, spin): how to pass the time up to the deadline (perf_counter s), the
        last `spin` s busy; by default a sleep, then a spin (the cycle process reads its pipe
        meanwhile)."""
        if self.free:
            return self._run_free(between)
        step, period, spin, stats = self.step, self.cycle_time, self.spin, self.stats
        clock, sleep = time.perf_counter, time.sleep
        deadline = clock() + period
        previous = float("nan")
        while True:
            if wait is not None:
                wait(deadline, spin)
            else:
                if deadline - clock() > spin:
                    sleep(deadline - clock() - spin)
                while clock() < deadline:
                    pass
            start = clock()
            late = start - deadline
            if late > period:
                missed = int(late // period)
                stats.overrun(missed)
                deadline += missed * period
            step()
            stats.record(start - previous, late, clock() - start)
            previous = start
            deadline += period
            if not between(deadline):
                return


    def _run_free(self, between: Callable[[float], bool]) -> None:
        """Cycle after cycle with no wait (simulated time runs ahead of the wall clock as far
        as the machine allows); between cycles `between` serves the parent for at least one
        message and one call, as on the deadline grid."""
        step, stats, clock = self.step, self.stats, time.perf_counter
        previous = float("nan")
        while True:
            start = clock()
            step()
            now = clock()
            stats.record(start - previous, 0.0, now - start)
            previous = start
            if not between(now):
                return
