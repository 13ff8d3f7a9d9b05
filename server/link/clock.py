"""The clocks that drive a controller's `step()`.

- `LockStepClock`: cycles back to back in the caller's thread, as fast as the CPU allows, fully
  deterministic; simulated time only. For tests and benchmarks.
- `ThreadedLockStepClock`: the lock-step clock on a thread of this process, with the surface
  of the real-time clock, so a device server can run on either (tests).
- `RealTimeClock` (realtime_clock.py, imported here): the controller lives in a cycle process
  of its own (cycle_process.py), stepped every `cycle_time` seconds of wall time, or back to
  back (`free`). The parent reaches it through `proxy` (the asynchronous LLI calls, answered
  between cycles), `send`/`recv` (application messages to and from the cyclic function's
  Mailbox) and `stats()` (timing figures).

A controller here is anything with `step()` and `cycle_time` (s): the pybullet backend
(`BulletController`) or a test's stand-in.
"""
from __future__ import annotations

import functools
import logging
import math
import queue
import threading
import time
from concurrent.futures import Future
from typing import Any, Callable

from landscape.server.cycle import process as cp
from landscape.server.link.realtime_clock import CycleProcessError, RealTimeClock

__all__ = ["LockStepClock", "ThreadedLockStepClock", "RealTimeClock", "CycleProcessError"]

log = logging.getLogger(__name__)


class LockStepClock:
    """Steps `controller` back to back: simulated time advances `cycle_time` per step, wall
    time is whatever the CPU needs. Runs in the caller's thread."""

    def __init__(self, controller: cp.Steppable):
        self.controller = controller
        self.cycle_time = float(controller.cycle_time)

    @property
    def time(self) -> float:
        """Simulated time of the controller, s."""
        return self.controller.time

    def step(self, n: int = 1) -> None:
        step = self.controller.step
        for _ in range(n):
            step()

    def run_for(self, seconds: float) -> int:
        """Run round(seconds / cycle_time) cycles; return that count."""
        n = round(seconds / self.cycle_time)
        self.step(n)
        return n

    def run_until(self, predicate: Callable[[], bool], timeout_s: float) -> bool:
        """Step until `predicate()` is true (checked before every cycle) or `timeout_s` of
        simulated time passed; return the predicate's last value."""
        step = self.controller.step
        for _ in range(math.ceil(timeout_s / self.cycle_time - 1e-9)):
            if predicate():
                return True
            step()
        return bool(predicate())


class ThreadedLockStepClock:
    """The lock-step clock free running on a thread of this process, with RealTimeClock's
    surface (proxy, call, send, on_message, set_event_func, between_cycles, stop), so a device
    server can run on either.

    factory(mailbox) builds the controller, here. Cycles run back to back; pace: at most this
    many simulated seconds per wall second (None: as fast as the CPU goes). Calls and messages
    are served between cycles, as the cycle process does, so the controller is only ever
    touched by the cycle thread. Messages and events go to a dispatch thread, as in
    RealTimeClock, so their handlers may make proxy calls.
    """

    def __init__(self, factory: Callable[[cp.Mailbox], cp.Steppable],
                 on_message: Callable[[Any], None] | None = None, pace: float | None = None,
                 call_timeout: float = 5.0):
        self._pace = pace
        self._mailbox = cp.Mailbox()
        self.controller = factory(self._mailbox)
        self.cycle_time = self.controller.cycle_time
        self._on_message = on_message
        self._event_func: Callable[[str], None] | None = None
        self._calls: queue.SimpleQueue = queue.SimpleQueue()
        self._dispatch_queue: queue.SimpleQueue = queue.SimpleQueue()
        self._running = True
        self._released = threading.Event()
        self._released.set()
        self._hold_at: float | None = None
        self.yield_period = 0.0005   # s of wall time between two hand-overs of the interpreter
        self.call_timeout = call_timeout
        self._threads = [threading.Thread(target=self._run, name="lockstep-cycle", daemon=True),
                         threading.Thread(target=self._dispatch, name="lockstep-dispatch",
                                          daemon=True)]
        for thread in self._threads:
            thread.start()

    @functools.cached_property
    def proxy(self):
        """A `Controller` whose asynchronous calls run on the cycle thread."""
        from landscape.server.link.controller_proxy import ControllerProxy  # needs the LLI types
        return ControllerProxy(self)

    def call(self, method: str, *args, timeout: float | None = None) -> Any:
        """Run `method(*args)` on the controller between cycles (cycle_process.serve_call)."""
        future: Future = Future()
        self._calls.put((future, method, args))
        return future.result(self.call_timeout if timeout is None else timeout)

    def between_cycles(self, func: Callable[..., Any], *args, timeout: float | None = None,
                       urgent: bool = False) -> Any:
        """Run `func(controller, *args)` on the cycle thread between two cycles: for what the
        LLI has no call for (the simulator's panel and sensors). Calls here run in order on
        the cycle thread itself, so `urgent` changes nothing."""
        return self.call(cp.RUN, func, args, timeout=timeout)

    def send(self, msg: Any) -> None:
        self._mailbox.inbox.append(msg)

    def set_event_func(self, func: Callable[[str], None] | None) -> None:
        self._event_func = func

    def stop(self) -> None:
        if self._running:
            self._running = False
            self._dispatch_queue.put(None)
            for thread in self._threads:
                thread.join(5.0)

    def hold(self) -> None:
        """Stop stepping (simulated time stands still) once the cycle under way, if one is,
        has ended: this returns after it. Calls and messages are still served. For tests that
        need a race to happen in a given order."""
        self._released.clear()
        self.between_cycles(lambda controller: None)   # served after the cycle under way

    def hold_at(self, seconds: float) -> None:
        """`hold` after the first cycle that brings the controller's time to `seconds`."""
        self._hold_at = seconds

    @property
    def held(self) -> bool:
        return not self._released.is_set()

    @property
    def pending(self) -> int:
        """Messages sent and not yet taken by the cyclic function."""
        return len(self._mailbox.inbox)

    def release(self) -> None:
        """Step again after `hold`."""
        self._released.set()

    def _run(self) -> None:
        step, outbox = self.controller.step, self._mailbox.outbox
        clock, sleep = time.monotonic, time.sleep
        started, cycles, yielded = clock(), 0, clock()
        try:
            while self._running:
                if self._released.is_set():
                    step()
                    cycles += 1
                    if self._hold_at is not None and self.controller.time >= self._hold_at:
                        self._hold_at = None
                        self._released.clear()
                else:
                    self._released.wait(0.001)
                if self._pace:  # keep simulated time from running ahead of the wall clock
                    ahead = cycles * self.cycle_time / self._pace - (clock() - started)
                    if ahead > 0:
                        sleep(ahead)
                while outbox:
                    self._dispatch_queue.put(outbox.popleft())
                while not self._calls.empty():
                    self._serve(*self._calls.get())
                # Let the server's threads have the interpreter now and then (not every cycle:
                # handing the GIL over costs more than a cycle of the simulation).
                if clock() - yielded > self.yield_period:
                    sleep(0)
                    yielded = clock()
        finally:
            for name in ("disable", "destroy"):
                try:
                    getattr(self.controller, name)()
                except Exception:
                    log.exception("controller %s failed while stopping", name)

    def _dispatch(self) -> None:
        while (item := self._dispatch_queue.get()) is not None:
            kind, payload = item
            handler = self._on_message if kind == cp.MSG else self._event_func
            if handler is not None:
                try:
                    handler(payload)
                except Exception:
                    log.exception("handling a %s from the cycle failed", kind)

    def _serve(self, future: Future, method: str, args: tuple) -> None:
        try:
            value = cp.serve_call(self.controller, self._mailbox, method, args)
        except Exception as exc:
            future.set_exception(exc)
        else:
            future.set_result(value)
