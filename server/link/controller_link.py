"""The device server's line to its controller, on any of three clocks (DESIGN.md section 7).

- "realtime": the controller and the Executor run in a cycle process of their own, stepped
  every cycle on wall-clock deadlines (clock.RealTimeClock).
- "fast": the same cycle process with no deadlines, cycle after cycle as fast as it goes:
  simulated time far ahead of the wall clock, for running long programs quickly; the server
  shares no interpreter with it, so both cores work.
- "lockstep": they run in this process on a thread that steps cycle after cycle as fast as it
  can (clock.ThreadedLockStepClock): deterministic physics, simulated time far
  ahead of the wall clock, a clock a test can hold and step. For tests.

`ControllerLink` offers the same surface on all three: `proxy` (the asynchronous LLI calls, served
between cycles), `send` (messages to the Executor), `between_cycles`, `feedback` (every
cycle's row, feedback.py) and `share` (large arrays for the cycle, without copying them
through the pipe). It watches the controller: the cycle process exiting, or its feedback
falling silent for `silence_cycles` cycles (on the fast clock, for FAST_SILENCE: its process
runs in the normal policy, which a busy machine may hold off the cores for tens of ms), is
reported once to `on_lost(reason)`. A silent
process is killed before it is reported: one that was only stalled must never wake up and
go on commanding the arm after the device has said it is lost. `restart()` starts a fresh
controller (after a loss); the feedback ring survives, so cycle numbers go on, and so does
the e-stop: a button pressed in the cell stays pressed for the new controller.
"""
from __future__ import annotations

import functools
import logging
import threading
import time
from typing import Any, Callable

from landscape.robot.controller import Capability
from landscape.server.config import CLOCKS, PROCESS_CLOCKS
from landscape.server.cycle.factory import build_controller
from landscape.server.cycle.feedback import WALL, FeedbackRing, Sample
from landscape.server.cycle.shared_array import SharedArrays
from landscape.server.errors import ControllerFailure
from landscape.server.link.clock import RealTimeClock, ThreadedLockStepClock

log = logging.getLogger(__name__)
FAST_SILENCE = 0.5   # s without feedback that count as a hung cycle process, fast clock
# A process says it is ready before its first cycle (it collects its garbage and tunes its
# scheduling in between): on a busy machine that took over 40 ms. Its first row may take this.
START_SILENCE = 2.0


class ControllerLink:
    """A controller on `clock`, its feedback ring, and a watch on its life.

    on_message(msg): the Executor's reports, in order, on the clock's dispatch thread.
    on_lost(reason): once per loss, on a thread of the link's (never a gRPC thread).
    pace: lock-step only, at most this many simulated seconds per wall second (None: flat out).
    silence_cycles: cycles without feedback that count as a hung cycle process (real time).
    backend: the controller backend (robot/backends.py) if not the cell file's.
    """

    def __init__(self, clock: str, cell_path: str | None, on_message: Callable[[Any], None],
                 on_lost: Callable[[str], None], pace: float | None = None,
                 silence_cycles: int = 10, backend: str | None = None):
        if clock not in CLOCKS:
            raise ValueError(f"unknown clock {clock!r}; choose one of {', '.join(CLOCKS)}")
        self.clock_kind = clock
        self._cell_path = cell_path
        self._backend = backend
        self._capabilities: frozenset[Capability] | None = None
        self._on_message = on_message
        self._on_lost = on_lost
        self._pace = pace
        self.silence_cycles = silence_cycles
        self.feedback = FeedbackRing()
        if clock == "realtime":   # a cycle with time to spare: whole rows, reads from the ring
            self.feedback.watch()
        self.lost: str | None = None        # why the controller was lost, until restart()
        self._lost_lock = threading.Lock()
        self._closing = False
        self._generation = 0                # which clock is current: a dead one's news is old
        self._clock = self._start_clock()
        self._watchdog: threading.Thread | None = None
        if clock in PROCESS_CLOCKS:
            self._watchdog = threading.Thread(target=self._watch, name="controller-watchdog",
                                              daemon=True)
            self._watchdog.start()

    def _start_clock(self):
        last = self.feedback.latest()   # the e-stop as the controller before this one left it
        self._generation += 1
        generation = self._generation
        factory = functools.partial(build_controller, self._cell_path, self.feedback,
                                    estop_pressed=last is not None and last.estop,
                                    backend_name=self._backend)
        if self.clock_kind in PROCESS_CLOCKS:
            return RealTimeClock(factory, on_message=self._on_message,
                                 free=self.clock_kind == "fast",
                                 on_failure=lambda why: self._lose(
                                     f"the cycle process died: {why.strip().splitlines()[-1]}"
                                     if why else "the cycle process died",
                                     generation=generation)).start()
        return ThreadedLockStepClock(factory, self._on_message, self._pace)

    # -- the clock's surface
    @property
    def clock(self):
        return self._clock

    @property
    def proxy(self):
        return self._clock.proxy

    @property
    def capabilities(self) -> frozenset[Capability]:
        """What the backend offers beyond the LLI (robot/controller.py), asked once."""
        if self._capabilities is None:
            self._capabilities = self.proxy.capabilities()
        return self._capabilities

    @property
    def cycle_time(self) -> float:
        return self._clock.cycle_time

    @property
    def tuning_problems(self) -> list[str]:
        """What the cycle process could not tune (real-time priority, timer slack)."""
        return list(getattr(self._clock, "tuning_problems", []))

    def send(self, msg: Any) -> None:
        self._clock.send(msg)

    def between_cycles(self, func, *args, timeout: float | None = None, urgent: bool = False):
        return self._clock.between_cycles(func, *args, timeout=timeout, urgent=urgent)

    def sample(self) -> Sample:
        """The newest cycle's feedback (never more than a cycle old); ControllerFailure before
        the first."""
        sample = self.feedback.latest()
        if sample is None:
            raise ControllerFailure("no feedback from the controller yet")
        return sample

    def share(self, arrays: dict) -> SharedArrays:
        """`arrays` (name -> ndarray) for the cycle: shared memory for a cycle process (the
        pipe then carries only their names), the arrays themselves on the lock-step thread."""
        return SharedArrays.create(arrays, shared=self.clock_kind in PROCESS_CLOCKS)

    def stats(self):
        return self._clock.stats() if hasattr(self._clock, "stats") else None

    def cycle_samples(self, seen: int):
        """The cycles after the first `seen` (StatsRing.since), None on a clock without
        statistics (lock-step)."""
        return self._clock.cycle_samples(seen) if hasattr(self._clock, "cycle_samples") else None

    @property
    def cycle_pid(self) -> int | None:
        """The cycle process's id, None on the lock-step clock (a thread of this process)."""
        return getattr(self._clock, "pid", None)

    # -- life
    def restart(self) -> None:
        """A fresh controller after a loss (the dead one is stopped first)."""
        with self._lost_lock:
            self._stop_clock()
            self._clock = self._start_clock()
            self.lost = None

    def stop(self) -> None:
        self._closing = True
        self._stop_clock()
        self.feedback.close()

    def _stop_clock(self) -> None:
        try:
            self._clock.stop()
        except Exception:
            log.exception("stopping the controller failed")

    def _lose(self, reason: str, kill: bool = False, generation: int | None = None) -> None:
        """Report the loss of the clock of `generation` (the current one if None). A process
        killed as silent reports its exit later, maybe after a restart: that is old news."""
        with self._lost_lock:
            if (self.lost is not None or self._closing
                    or generation not in (None, self._generation)):
                return
            self.lost = reason
            if kill:   # before anyone hears of the loss (a stalled process may resume)
                self._clock.kill()
        log.error("controller lost: %s", reason)
        self._on_lost(reason)

    def _watch(self) -> None:
        """The ring must advance; `silence_cycles` cycles without a row is a hang (on the fast
        clock, FAST_SILENCE; before a new process's first row, START_SILENCE). Silence counts
        from when the newest row was written (its time stamp), and the watchdog looks when
        that row would be too old: about once per limit while rows come, where a look every
        cycle took the interpreter from the server 250 times a second (issue 31 item 1)."""
        cycle = self._clock.cycle_time
        limit = self.silence_cycles * cycle
        if self.clock_kind == "fast":
            limit = max(limit, FAST_SILENCE)
        generation, first_row, seen = None, True, self.feedback.head
        since = looked = time.monotonic()
        while not self._closing:
            due = since + (START_SILENCE if first_row else limit)
            time.sleep(min(limit, max(cycle, due - time.monotonic())))
            head, now = self.feedback.head, time.monotonic()
            if self._generation != generation:    # a new process: judged from its first row
                generation, first_row, seen, since = self._generation, True, head, now
            if head != seen or self.lost is not None:
                first_row = first_row and head == seen
                seen, since = head, self._written(head, looked, now)
            elif now - since > (START_SILENCE if first_row else limit):
                alive = self._clock.alive
                self._lose(f"the cycle process sent no feedback for {now - since:.3f} s"
                           + (" (killed)" if alive else " and exited"), kill=True,
                           generation=generation)
            looked = now

    def _written(self, sequence: int, looked: float, now: float) -> float:
        """When (monotonic s) row `sequence`, new since the look at `looked`, was written: by
        its time stamp, kept within (looked, now] (a wall clock that stepped is trusted no
        further)."""
        row = self.feedback.row(sequence)
        if row is None:
            return now
        return min(now, max(looked, now - (time.time() - float(row[WALL]))))

