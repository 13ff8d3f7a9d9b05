"""The cycle process's own side: its entry point, the pipe to its parent read and served between
cycles, the LLI's asynchronous task, and its tuning for latency.

`RealTimeClock` (realtime_clock.py) spawns `child_main`; the vocabulary both sides share (the
wire protocol, the Mailbox, the call dispatch) and the cycle loop are in cycle_process.py.
"""
from __future__ import annotations

import faulthandler
import gc
import os
import queue
import select
import signal
import struct
import sys
import threading
import time
import traceback
from collections import deque
from multiprocessing.reduction import ForkingPickler
from typing import Any, Callable

from landscape.server import lifeline
from landscape.server.cycle.process import (CALL, FATAL, LATE_IMPORTS, MSG, READY, REPLY,
                                         RESET_STATS, RUN_URGENT, SIM_TIME, SLOW_CALLS, STOP,
                                         CycleLoop, Mailbox, Steppable, serve_call)
from landscape.server.cycle.stats import StatsRing

# s a file being stored (a recording) may still take when the loop ended unasked (a signal, the
# server gone): the drives are off already, and the cycle process must be gone within a second
# of its server. The kernel's parent-death signal is a SIGTERM that comes while the dying
# server's threads end, before the child is seen reparented: it cannot tell the two apart.
ORPHAN_GRACE = 0.3
GONE = "the device server is gone"
# s of wall time between two sends of the cycle's reports on the free-running clock, at most
# (--clock fast: a cycle every ~0.1 ms): each send wakes the server, whose work then competes
# with the cycle's; the reports still come in order, within half a real cycle of their own.
# What the parent sends is read every cycle all the same (a stop never waits).
FREE_FLUSH_PERIOD = 0.002


class _AsyncTask:
    """The LLI's asynchronous task, for calls that take long (file I/O): one thread at normal
    priority, one call at a time. The loop thread only hands calls over and collects results,
    so a slow call delays no cycle (the short GIL switch interval set by `child_main` bounds
    how long this thread can keep the loop waiting)."""

    def __init__(self):
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self.busy = False
        self.result: tuple | None = None   # (call_id, ok, value), set by the thread
        threading.Thread(target=self._run, name="lli-async", daemon=True).start()

    def submit(self, call_id: int, func: Callable, args: tuple) -> None:
        self.busy = True
        self._jobs.put((call_id, func, args))

    def take(self) -> tuple | None:
        """The finished call's (call_id, ok, value), once; None while running or idle."""
        result, self.result = self.result, None
        if result is not None:
            self.busy = False
        return result

    def wait(self, timeout: float) -> None:
        end = time.monotonic() + timeout
        while self.busy and self.result is None and time.monotonic() < end:
            time.sleep(0.01)

    def _run(self) -> None:
        try:  # threads inherit the policy of their creator; this one must not compete
            os.sched_setscheduler(0, os.SCHED_OTHER, os.sched_param(0))
        except (OSError, AttributeError):
            pass
        while True:
            call_id, func, args = self._jobs.get()
            try:
                self.result = (call_id, True, func(*args))
            except Exception as exc:
                self.result = (call_id, False, exc)


class _Frames:
    """The parent's messages, as multiprocessing's Connection frames them (a 4-byte big-endian
    length, or -1 and an 8-byte one, then the pickle), taken only once whole. A large message
    is written in several writes, and a busy parent may take its time between them:
    Connection.recv would wait for the rest inside a cycle; this reads what has arrived and
    keeps it for later."""

    def __init__(self, fd: int):
        self.fd = fd
        self.buffer = bytearray()
        self.ended = False   # the parent closed its end, or died
        # Asked every cycle: a poll object registered once costs half a select.
        self._arrived = select.poll()
        self._arrived.register(fd, select.POLLIN)

    def fill(self, limit: int = 1 << 20) -> None:
        """Read what has arrived (up to `limit` bytes), never waiting for more."""
        while limit > 0 and self._arrived.poll(0):
            try:
                chunk = os.read(self.fd, min(limit, 1 << 18))
            except OSError:
                chunk = b""
            if not chunk:
                self.ended = True
                return
            self.buffer += chunk
            limit -= len(chunk)

    def next(self) -> Any | None:
        """The oldest whole message, unpickled; None until one has arrived whole."""
        buffer = self.buffer
        if len(buffer) < 4:
            return None
        size, start = struct.unpack_from("!i", buffer)[0], 4
        if size == -1:
            if len(buffer) < 12:
                return None
            size, start = struct.unpack_from("!Q", buffer, 4)[0], 12
        if len(buffer) < start + size:
            return None
        item = ForkingPickler.loads(buffer[start:start + size])
        del buffer[:start + size]
        return item


class _Server:
    """The child's side of the pipe, between cycles: sends what the cyclic function posted,
    reads what the parent sent, and serves calls in order within the time budget."""

    def __init__(self, conn, controller, mailbox: Mailbox, stats: StatsRing, parent_pid: int,
                 guard: float, flush_period: float = 0.0):
        self.conn = conn
        self.fd = conn.fileno()
        self.frames = _Frames(self.fd)
        self.controller = controller
        self.mailbox = mailbox
        self.stats = stats
        self.parent_pid = parent_pid
        self.guard = guard
        self.calls: deque = deque()   # (call_id, method, args) not served yet
        self.urgent: deque = deque()  # the same, RUN_URGENT: served first, never held back
        self.async_task = _AsyncTask()
        self.running = True
        self.ended_by = ""            # why the loop ended, unless the parent asked (STOP)
        self.cycles = 0
        self.modules: frozenset[str] = frozenset()   # what the loop starts with
        self.flush_period = flush_period   # s between two sends of reports, at least
        self._flushed = 0.0                # perf_counter s of the last

    def between(self, deadline: float) -> bool:
        """deadline: the next cycle's (perf_counter s), or now on the free-running clock."""
        self.cycles += 1
        if self.mailbox.outbox and deadline - self._flushed >= self.flush_period:
            self._flushed = deadline
            self.flush()
        done = self.async_task.take()
        if done is not None:
            self._reply(*done)
        self._read(deadline)
        self._serve(deadline)
        if self.cycles % 64 == 0 and os.getppid() != self.parent_pid:
            self.end(GONE)  # reparented: the parent died without closing the pipe
        return self.running

    def wait(self, deadline: float, spin: float) -> None:
        """Until the deadline (perf_counter s), take what the parent sends as it arrives, so a
        message sent any time before the cycle is in the mailbox for it (a stop reaches the arm
        in the next cycle): asleep in select, then the last `spin` s polling it."""
        clock, fd, ready = time.perf_counter, self.fd, select.select
        while self.running and (remaining := deadline - spin - clock()) > 0:
            if ready((fd,), (), (), remaining)[0]:
                self._read(deadline - spin + self.guard)
        while clock() < deadline:
            if ready((fd,), (), (), 0)[0]:
                self._read(deadline + self.guard)

    def _read(self, deadline: float) -> None:
        # At least one item per cycle, so even an overloaded loop still hears STOP.
        clock, count = time.perf_counter, 0
        self.frames.fill()
        while self.running:
            if count and clock() > deadline - self.guard:
                return
            item = self.frames.next()
            if item is None:
                if self.frames.ended:   # never set back to True: SIGTERM may have cleared it
                    self.end(GONE)
                return
            count += 1
            tag = item[0]
            if tag == MSG:
                self.mailbox.inbox.append(item[1])
            elif tag == CALL:
                (self.urgent if item[2] == RUN_URGENT else self.calls).append(item[1:])
            elif tag == STOP:
                self.running = False

    def end(self, why: str) -> None:
        """End the loop after this cycle, not asked by the parent: `why` is said on stderr."""
        self.running = False
        self.ended_by = self.ended_by or why

    def _serve(self, deadline: float) -> None:
        # The urgent lane first (its calls are short), whatever the asynchronous task does.
        while self.urgent:
            self._answer(*self.urgent.popleft())
        # In order; a slow call goes to the asynchronous task and holds the later ones back.
        clock, count = time.perf_counter, 0
        while self.calls and not self.async_task.busy:
            if count and clock() > deadline - self.guard:
                return
            call_id, method, args = self.calls.popleft()
            count += 1
            if method in SLOW_CALLS:
                self.async_task.submit(call_id, getattr(self.controller, method), args)
                return
            self._answer(call_id, method, args)

    def _answer(self, call_id: int, method: str, args: tuple) -> None:
        try:
            value = self._call(method, args)
        except Exception as exc:  # the parent re-raises it
            self._reply(call_id, False, exc)
        else:
            self._reply(call_id, True, value)

    def flush(self) -> None:
        """Send what the cycle posted, as far as the pipe takes it now."""
        outbox = self.mailbox.outbox
        while outbox:
            # A full pipe (parent not reading) would block send(): keep the rest for later.
            if not select.select((), (self.fd,), (), 0)[1]:
                return
            self._send(outbox.popleft())

    def _send(self, item: tuple) -> None:
        try:
            self.conn.send(item)
        except (BrokenPipeError, ConnectionError, EOFError):
            self.end(GONE)

    def _call(self, method: str, args: tuple) -> Any:
        if method == RESET_STATS:
            return self.stats.reset()
        if method == SIM_TIME:
            return getattr(self.controller, "time", None)
        if method == LATE_IMPORTS:
            return sorted(set(sys.modules) - self.modules)
        return serve_call(self.controller, self.mailbox, method, args)

    def _reply(self, call_id: int, ok: bool, value: Any) -> None:
        if self.mailbox.outbox:   # the reports held back (flush_period) go first, as posted
            self.flush()
        try:
            self.conn.send((REPLY, call_id, ok, value))
        except (BrokenPipeError, ConnectionError, EOFError):
            self.end(GONE)
        except Exception as exc:  # the value did not pickle; nothing was written yet
            error = RuntimeError(f"a {type(value).__name__} did not pickle: {exc!r}")
            self._send((REPLY, call_id, False, error))


def tune_for_latency(rt_priority: int | None = None) -> list[str]:
    """Best effort, Linux: 1 ns timer slack (sleeps end closer to when asked), and optionally
    the SCHED_FIFO real-time policy at `rt_priority` (1..99; needs the privilege). Returns what
    could not be done, for the caller to report."""
    problems = []
    try:
        import ctypes
        if ctypes.CDLL(None, use_errno=True).prctl(29, 1, 0, 0, 0) != 0:  # PR_SET_TIMERSLACK
            problems.append("timer slack unchanged")
    except (OSError, AttributeError):
        problems.append("timer slack unchanged")
    if rt_priority is not None:
        try:
            os.sched_setscheduler(0, os.SCHED_FIFO, os.sched_param(rt_priority))
        except (OSError, AttributeError) as exc:
            problems.append(f"SCHED_FIFO refused: {exc}")
    return problems


def _shutdown(controller, async_task: _AsyncTask | None = None, grace: float = 0.0) -> bool:
    """Leave the robot safe: disable at once, whatever state we are in; then let a file being
    stored finish (at most `grace` s) and destroy. Returns whether the disable went through."""
    disabled = _call_quietly(controller, "disable")
    if async_task is not None:
        async_task.wait(grace)
    _call_quietly(controller, "destroy")
    return disabled


def _call_quietly(controller, name: str) -> bool:
    method = getattr(controller, name, None)
    if method is None:
        return True
    try:
        method()
    except Exception:
        traceback.print_exc()
        return False
    return True


def child_main(factory: Callable[[Mailbox], Steppable], conn, stats: StatsRing,
               cycle_time: float | None, parent_pid: int, spin: float, guard: float,
               rt_priority: int | None, free: bool = False) -> None:
    """Entry point of the cycle process (see the module docstring)."""
    server: _Server | None = None

    def on_sigterm(*_):
        if server is None:
            raise SystemExit(1)  # still building: clean up on the way out
        server.end("SIGTERM")  # the loop ends after this cycle

    faulthandler.enable()   # a crash in native code (pybullet) leaves its stack on stderr
    # The parent may block signals in its threads (it waits for them with sigwait); a spawned
    # child inherits that mask, and must not: it has handlers of its own.
    signal.pthread_sigmask(signal.SIG_SETMASK, ())
    # Ctrl-C in a terminal reaches the whole process group; the parent decides when we stop.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, on_sigterm)
    # The server's death, however it dies (SIGKILL too), reaches us as a SIGTERM: the loop
    # ends within a cycle and the drives go off.
    lifeline.bind_to_parent(parent_pid, signal.SIGTERM)
    controller = None
    try:
        mailbox = Mailbox()
        controller = factory(mailbox)
        own = getattr(controller, "cycle_time", None)
        if cycle_time is None:
            cycle_time = own if own is not None else 0.004
        elif own is not None and abs(own - cycle_time) > 1e-12:
            raise ValueError(f"the clock's cycle time {cycle_time} s differs from the "
                             f"controller's {own} s")
        loop = CycleLoop(controller.step, cycle_time, stats, spin, free)
        server = _Server(conn, controller, mailbox, stats, parent_pid, guard,
                         FREE_FLUSH_PERIOD if free else 0.0)
        problems = tune_for_latency(rt_priority)
        conn.send((READY, {"pid": os.getpid(), "cycle_time": loop.cycle_time,
                           "tuning_problems": problems}))
    except BaseException:
        _fatal(conn, traceback.format_exc())
        if controller is not None:
            _shutdown(controller)
        raise SystemExit(1)
    # Move everything built so far out of the collector's sight: later collections stay short.
    gc.collect()
    gc.freeze()
    # The asynchronous thread must hand the GIL back quickly when the loop wakes up.
    sys.setswitchinterval(0.0001)
    server.modules = frozenset(sys.modules)
    code = 0
    try:
        loop.run(server.between, server.wait)
    except BaseException:
        _fatal(conn, traceback.format_exc())
        code = 1
    finally:
        unasked = server.ended_by
        disabled = _shutdown(controller, server.async_task, ORPHAN_GRACE if unasked else 30.0)
        if unasked:   # the server may not be there to read the pipe: say it on its stderr
            print(f"landscape cycle process: {unasked}: "
                  f"{'drives disabled' if disabled else 'disabling the drives FAILED'}",
                  file=sys.stderr, flush=True)
        server.flush()
        conn.close()
    raise SystemExit(code)


def _fatal(conn, text: str) -> None:
    try:
        conn.send((FATAL, text))
    except Exception:
        pass
