"""The device server's line to its controller, on either clock (DESIGN.md section 7).

- "realtime": the controller and the Executor run in a cycle process of their own, stepped
  every cycle on wall-clock deadlines (landscape.sim.clock.RealTimeClock).
- "lockstep": they run in this process on a thread that steps cycle after cycle as fast as it
  can; deterministic physics, simulated time far ahead of the wall clock. For tests.

Both offer the same surface: `proxy` (the asynchronous LLI calls, served between cycles),
`on_message` (the Executor's posts) and `stop()`.
"""
from __future__ import annotations

import functools
import logging
import queue
import threading
import time
from concurrent.futures import Future
from typing import Any, Callable

from landscape.server.executor import Executor
from landscape.sim.cycle_process import CONTROLLER_CALLS, MSG, PLUG_EVENT_FUNC, Mailbox

log = logging.getLogger(__name__)

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
        from landscape.sim.clock import RealTimeClock
        return RealTimeClock(factory, on_message=on_message).start()
    if clock == "lockstep":
        return LockStepLink(factory, on_message, pace)
    raise ValueError(f"unknown clock {clock!r}; choose one of {', '.join(CLOCKS)}")


class LockStepLink:
    """The controller on a thread of this process, stepped back to back (lock-step clock).

    Calls and messages are served between cycles, as the cycle process does, so the controller
    is only ever touched by this thread. Messages and events are handed to a dispatch thread,
    as RealTimeClock does, so their handlers may make proxy calls.
    """

    def __init__(self, factory: Callable[[Mailbox], Any], on_message: Callable[[Any], None],
                 pace: float | None = None):
        self._pace = pace
        self._mailbox = Mailbox()
        self.controller = factory(self._mailbox)
        self.cycle_time = self.controller.cycle_time
        self._on_message = on_message
        self._event_func: Callable[[str], None] | None = None
        self._calls: queue.SimpleQueue = queue.SimpleQueue()
        self._dispatch_queue: queue.SimpleQueue = queue.SimpleQueue()
        self._running = True
        self.call_timeout = 5.0
        self._threads = [threading.Thread(target=self._run, name="lockstep-cycle", daemon=True),
                         threading.Thread(target=self._dispatch, name="lockstep-dispatch",
                                          daemon=True)]
        for thread in self._threads:
            thread.start()

    @functools.cached_property
    def proxy(self):
        from landscape.sim.controller_proxy import ControllerProxy
        return ControllerProxy(self)

    def call(self, method: str, *args, timeout: float | None = None) -> Any:
        if method not in CONTROLLER_CALLS and method != PLUG_EVENT_FUNC:
            raise AttributeError(f"{method!r} is not an asynchronous controller call")
        future: Future = Future()
        self._calls.put((future, method, args))
        return future.result(self.call_timeout if timeout is None else timeout)

    def between_cycles(self, func: Callable[[Any], Any], timeout: float | None = None) -> Any:
        """Run `func(controller)` on the cycle thread between two cycles (for the operator's
        panel and tests: pybullet must only ever be touched from that thread)."""
        future: Future = Future()
        self._calls.put((future, func, ()))
        return future.result(self.call_timeout if timeout is None else timeout)

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

    def _run(self) -> None:
        step, outbox = self.controller.step, self._mailbox.outbox
        started, cycles = time.monotonic(), 0
        try:
            while self._running:
                step()
                cycles += 1
                if self._pace:  # keep simulated time from running ahead of the wall clock
                    ahead = cycles * self.cycle_time / self._pace - (time.monotonic() - started)
                    if ahead > 0:
                        time.sleep(ahead)
                while outbox:
                    self._dispatch_queue.put(outbox.popleft())
                while not self._calls.empty():
                    self._serve(*self._calls.get())
                time.sleep(0)  # let the server's threads have the interpreter between cycles
        finally:
            for name in ("disable", "destroy"):
                try:
                    getattr(self.controller, name)()
                except Exception:
                    log.exception("controller %s failed while stopping", name)

    def _dispatch(self) -> None:
        while (item := self._dispatch_queue.get()) is not None:
            kind, payload = item
            handler = self._on_message if kind == MSG else self._event_func
            if handler is not None:
                try:
                    handler(payload)
                except Exception:
                    log.exception("handling a %s from the cycle failed", kind)

    def _serve(self, future: Future, method: str, args: tuple) -> None:
        try:
            if callable(method):
                value = method(self.controller)
            elif method == PLUG_EVENT_FUNC:
                value = self.controller.plug_event_func(self._mailbox.event if args[0] else None)
            else:
                value = getattr(self.controller, method)(*args)
        except Exception as exc:
            future.set_exception(exc)
        else:
            future.set_result(value)
