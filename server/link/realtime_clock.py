"""The real-time clock: a controller in a cycle process of its own (cycle_process.py), stepped
every cycle on wall-clock deadlines, or back to back. See RealTimeClock; clock.py has the
other clocks.
"""
from __future__ import annotations

import itertools
import logging
import multiprocessing
import os
import queue
import threading
import traceback
from typing import Any, Callable

from landscape.server.cycle import child as cycle_child
from landscape.server import lifeline
from landscape.server.cycle import process as cp
from landscape.server.cycle.stats import CycleStats, StatsRing

log = logging.getLogger(__name__)


class CycleProcessError(RuntimeError):
    """The cycle process failed to start, died, or raised in a cycle (its traceback included)."""


class RealTimeClock:
    """Runs a controller in its own process, stepped every `cycle_time` s on absolute deadlines.

    factory: picklable (a top-level function or functools.partial of one), called in the child
      as `factory(mailbox)` with the child's `cycle_process.Mailbox`; it builds and returns the
      controller (and its cyclic function, which may keep the mailbox to talk to the parent).
      pybullet is thus created in the child, never in the parent.
    cycle_time: s, a multiple of 0.2 ms; None takes the controller's own `cycle_time` (4 ms for
      the default cell). If given, it must equal the controller's.
    on_message: if given, called with each message the cyclic function posts (on a dispatch
      thread of the parent); otherwise read them with `recv`.
    on_failure: if given, called once (on the dispatch thread) with a description when the
      cycle process ends without `stop()` having asked it to: its traceback, or how it exited.
      The robot is then disabled (the child disables on its way out) or its process is gone.
    call_timeout: s, default wait for a proxy call's answer.
    spin: s, the last part of each wait done by spinning rather than sleeping (a sleep on this
      class of machine wakes up to ~0.4 ms late; the spin costs spin / cycle_time of a core).
    guard: s, requests are only started while at least this much remains before the next
      deadline (one per cycle is always served, so the loop stays reachable when overloaded).
    window: cycles the percentiles of `stats()` cover (2**16 is 262 s at 4 ms).
    rt_priority: the child asks for the SCHED_FIFO real-time policy at this priority (1..99;
      50 as ros2_control does; None: stay in the normal policy). Without the privilege it runs
      anyway and says so in `tuning_problems`. Measured on the 2-core development VM with
      the parent busy (bench/bench_cycle.py, 60 s): late 0.006 ms at p99 with SCHED_FIFO,
      2 ms at p99 and 72 overruns in the normal policy.
    free: no deadlines: cycles back to back, as fast as the process goes (the lock-step speed
      of a cycle process, for long programs; the server shares no interpreter with it). Always
      in the normal policy (a free-running loop under SCHED_FIFO would starve the machine).

    Thread-safe: any parent thread may call `proxy` methods, `send`, `recv` and `stats`.
    """

    def __init__(self, factory: Callable[[cp.Mailbox], cp.Steppable],
                 cycle_time: float | None = None, *,
                 on_message: Callable[[Any], None] | None = None,
                 on_failure: Callable[[str], None] | None = None,
                 call_timeout: float = 5.0, start_timeout: float = 60.0,
                 spin: float = 0.0005, guard: float = 0.001, window: int = 1 << 16,
                 rt_priority: int | None = 50, free: bool = False):
        self._factory = factory
        self._cycle_time = None if cycle_time is None else cp.check_cycle_time(cycle_time)
        self._on_message = on_message
        self._on_failure = on_failure
        self._stopping = False
        self.call_timeout = call_timeout
        self._start_timeout = start_timeout
        self._spin, self._guard, self._rt_priority = spin, guard, rt_priority
        self.free = free
        self.tuning_problems: list[str] = []  # what the child could not tune (cycle_process)
        self._stats = StatsRing(window)
        self._process = None
        self._conn = None
        self._send_lock = threading.Lock()
        self._pending: dict[int, _Pending] = {}
        self._pending_lock = threading.Lock()
        self._ids = itertools.count(1)
        # C-level queues: the reader's hand-over to the dispatch thread (a tag event's way to
        # its subscribers) costs no Python-level lock and condition (issue 31 item 6).
        self._inbox: queue.SimpleQueue = queue.SimpleQueue()
        self._callbacks: queue.SimpleQueue = queue.SimpleQueue()
        self._event_func: Callable[[str], None] | None = None
        self._threads: list[threading.Thread] = []
        self._proxy = None
        self._closed = False  # set when the pipe to the child ends
        self.error: str | None = None  # the child's traceback, if it failed

    # -- life cycle
    def start(self) -> "RealTimeClock":
        """Spawn the cycle process, wait until its controller is built and the loop starts."""
        if self._process is not None:
            raise RuntimeError("already started")
        ctx = multiprocessing.get_context("spawn")
        parent_end, child_end = ctx.Pipe(duplex=True)
        self._process = ctx.Process(
            target=cycle_child.child_main, name="landscape-cycle", daemon=True,
            args=(self._factory, child_end, self._stats, self._cycle_time, os.getpid(),
                  self._spin, self._guard, None if self.free else self._rt_priority, self.free))
        lifeline.start(self._process)
        child_end.close()  # only the child holds it now: its death reads as EOF here
        self._conn = parent_end
        ready = self._wait_ready()
        self._cycle_time = ready["cycle_time"]
        self.tuning_problems = ready["tuning_problems"]
        for target, name in ((self._read, "cycle-reader"), (self._dispatch, "cycle-dispatch")):
            thread = threading.Thread(target=target, name=name, daemon=True)
            thread.start()
            self._threads.append(thread)
        return self

    def _wait_ready(self) -> dict:
        tag, rest = None, [f"no answer within {self._start_timeout} s"]
        try:
            if self._conn.poll(self._start_timeout):
                tag, *rest = self._conn.recv()
        except (EOFError, OSError):
            rest = ["it exited"]
        if tag == cp.READY:
            return rest[0]
        self.error = rest[0]
        self._kill()
        self._conn.close()
        self._closed = True
        raise CycleProcessError(f"the cycle process did not start (exit code "
                                f"{self._process.exitcode}):\n{self.error}")

    def stop(self, timeout: float = 5.0) -> int | None:
        """Ask the child to stop (it disables and destroys its controller), wait for it, and
        return its exit code. Terminates it if it does not exit within `timeout` s."""
        if self._process is None:
            return None
        if self._conn.closed:  # never started, or stopped already
            return self._process.exitcode
        self._stopping = True
        try:
            self._write((cp.STOP,))
        except CycleProcessError:
            pass  # already gone
        self._process.join(timeout)
        if self._process.is_alive():
            self._kill()
        self._callbacks.put(None)  # ends the dispatch thread; the reader ends on EOF
        for thread in self._threads:
            if thread is not threading.current_thread():
                thread.join(1.0)
        self._conn.close()
        return self._process.exitcode

    def kill(self) -> None:
        """SIGKILL the cycle process now, stopped or not: it runs no further instruction (its
        arm, in the simulator, is gone with it). The loss is reported as for any exit."""
        if self._process is not None and self._process.is_alive():
            self._process.kill()

    def _kill(self) -> None:
        self._process.terminate()
        self._process.join(2.0)
        if self._process.is_alive():
            self._process.kill()
            self._process.join()

    def __enter__(self) -> "RealTimeClock":
        return self.start()

    def __exit__(self, *exc) -> None:
        self.stop()

    # -- state
    @property
    def cycle_time(self) -> float | None:
        """s; known once started if it was left to the controller."""
        return self._cycle_time

    @property
    def pid(self) -> int | None:
        return self._process.pid if self._process else None

    @property
    def alive(self) -> bool:
        return self._process is not None and self._process.is_alive()

    def stats(self) -> CycleStats:
        """Timing figures so far (read from shared memory; costs the cycle nothing)."""
        return self._stats.snapshot(self._cycle_time or float("nan"))

    def cycle_samples(self, seen: int):
        """The cycles after the first `seen` (stats.StatsRing.since); costs the cycle nothing."""
        return self._stats.since(seen)

    def reset_stats(self) -> None:
        """Start the figures afresh (e.g. after a warm-up)."""
        self.call(cp.RESET_STATS)

    def sim_time(self) -> float | None:
        """The controller's simulated time, s (None if it has no `time`)."""
        return self.call(cp.SIM_TIME)

    def late_imports(self) -> list[str]:
        """The modules the cycle process imported since its loop started (should be none)."""
        return self.call(cp.LATE_IMPORTS)

    def between_cycles(self, func: Callable[..., Any], *args, timeout: float | None = None,
                       urgent: bool = False) -> Any:
        """Run `func(controller, *args)` in the cycle process between two cycles and return
        its result: for what the LLI has no call for (the simulator's panel and sensors).
        `func` and the arguments must pickle (a top-level function of a module the cycle
        process has loaded already: an import there would cost cycles); keep it short.
        `urgent`: in the cycle process's urgent lane, never behind a slow call."""
        return self.call(cp.RUN_URGENT if urgent else cp.RUN, func, args, timeout=timeout)

    # -- the two channels
    @property
    def proxy(self):
        """A `Controller` whose asynchronous calls run in the cycle process."""
        if self._proxy is None:
            from landscape.server.link.controller_proxy import ControllerProxy  # needs the LLI types
            self._proxy = ControllerProxy(self)
        return self._proxy

    def call(self, method: str, *args, timeout: float | None = None) -> Any:
        """Run `method(*args)` on the controller between cycles and return its result (or
        raise its exception). Blocks up to `timeout` s (default `call_timeout`)."""
        pending = _Pending()
        call_id = next(self._ids)
        with self._pending_lock:
            if self._closed or self._conn is None:
                raise CycleProcessError("the cycle process is not running"
                                        + (f":\n{self.error}" if self.error else ""))
            self._pending[call_id] = pending
        try:
            self._write((cp.CALL, call_id, method, args))
            if not pending.done.wait(self.call_timeout if timeout is None else timeout):
                raise TimeoutError(f"{method} got no answer from the cycle process")
        finally:
            with self._pending_lock:
                self._pending.pop(call_id, None)
        if not pending.ok:
            raise pending.value
        return pending.value

    def send(self, msg: Any) -> None:
        """Queue a message (any picklable object) for the cyclic function's `Mailbox.poll()`;
        it is delivered between cycles, in order. Raises CycleProcessError once the child is
        gone (a message sent just before it went may be lost)."""
        self._write((cp.MSG, msg))

    def recv(self, timeout: float | None = None) -> Any:
        """The next message the cyclic function posted; TimeoutError after `timeout` s."""
        if self._on_message is not None:
            raise RuntimeError("messages go to on_message")
        try:
            return self._inbox.get(timeout=timeout)
        except queue.Empty:
            raise TimeoutError("no message from the cycle process") from None

    def set_event_func(self, func: Callable[[str], None] | None) -> None:
        """Where the controller's events go (the proxy's plug_event_func uses it)."""
        self._event_func = func

    # -- the parent's threads
    def _write(self, item: tuple) -> None:
        try:
            with self._send_lock:
                self._conn.send(item)
        except OSError as exc:  # closed here, or the child's end is gone
            raise CycleProcessError(f"the cycle process is not running: {exc!r}") from None

    def _read(self) -> None:
        """Reader thread: answers to callers, messages and events to their queues."""
        while True:
            try:
                item = self._conn.recv()
            except (EOFError, OSError):
                break
            tag = item[0]
            if tag == cp.REPLY:
                _, call_id, ok, value = item
                with self._pending_lock:
                    pending = self._pending.get(call_id)
                if pending is not None:  # else its caller timed out
                    pending.ok, pending.value = ok, value
                    pending.done.set()
            elif tag == cp.MSG:
                if self._on_message is not None:
                    self._callbacks.put((self._on_message, item[1]))
                else:
                    self._inbox.put(item[1])
            elif tag == cp.EVENT:
                if self._event_func is not None:
                    self._callbacks.put((self._event_func, item[1]))
            elif tag == cp.FATAL:
                self.error = item[1]
        self._fail_pending()
        if not self._stopping and self._on_failure is not None:
            self._process.join(1.0)  # for its exit code
            why = self.error or f"the cycle process exited (code {self._process.exitcode})"
            self._callbacks.put((self._on_failure, why))

    def _fail_pending(self) -> None:
        with self._pending_lock:
            self._closed = True
            for pending in self._pending.values():
                pending.ok = False
                pending.value = CycleProcessError("the cycle process exited"
                                                  + (f":\n{self.error}" if self.error else ""))
                pending.done.set()

    def _dispatch(self) -> None:
        """Dispatch thread: user callbacks run here, so they may make proxy calls."""
        while (job := self._callbacks.get()) is not None:
            func, arg = job
            try:
                func(arg)
            except Exception:
                traceback.print_exc()


class _Pending:
    __slots__ = ("done", "ok", "value")

    def __init__(self):
        self.done = threading.Event()
        self.ok = False
        self.value: Any = None
