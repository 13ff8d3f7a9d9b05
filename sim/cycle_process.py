"""The cycle process: a controller stepped on absolute deadlines, serving its parent between cycles.

`RealTimeClock` (clock.py) starts `child_main` in a process of its own (spawn), so that the
server's Python threads never hold a GIL the cycle needs (DESIGN.md section 7).

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

The child exits when told to, on SIGTERM, and when its parent is gone: the pipe reports EOF
once the parent's end is closed (the kernel closes it when the parent dies), and the parent pid
is checked as well, so no orphan keeps stepping a robot.
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
from typing import Any, Callable, Protocol

from landscape.sim.cycle_stats import StatsRing

CALL, MSG, STOP, READY, REPLY, EVENT, FATAL = (
    "call", "msg", "stop", "ready", "reply", "event", "fatal")

# The asynchronous LLI calls the parent may make (LLI 5.3.1); get/set belong to the cycle.
CONTROLLER_CALLS = frozenset({
    "init", "home", "enable", "disable", "state", "ioctrl",
    "get_din_id", "get_dout_id", "read_dio", "write_dout",
    "io_map", "read_io_unit", "write_io_unit", "sensor_map", "read_sensor", "tare_sensor",
    "forward_kin", "reverse_kin", "rec_init", "rec_start", "rec_stop", "rec_store",
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


def check_cycle_time(cycle_time: float) -> float:
    """The LLI's rule (3.5.1): a positive multiple of 0.2 ms. Returns it as float, in s."""
    ticks = round(cycle_time / 0.0002)
    if ticks < 1 or abs(ticks * 0.0002 - cycle_time) > 1e-9:
        raise ValueError(f"cycle time {cycle_time!r} s is not a positive multiple of 0.2 ms")
    return float(cycle_time)


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

    def fill(self, limit: int = 1 << 20) -> None:
        """Read what has arrived (up to `limit` bytes), never waiting for more."""
        while limit > 0 and select.select((self.fd,), (), (), 0)[0]:
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
                 guard: float):
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
        self.cycles = 0
        self.modules: frozenset[str] = frozenset()   # what the loop starts with

    def between(self, deadline: float) -> bool:
        self.cycles += 1
        self._flush()
        done = self.async_task.take()
        if done is not None:
            self._reply(*done)
        self._read(deadline)
        self._serve(deadline)
        if self.cycles % 64 == 0 and os.getppid() != self.parent_pid:
            self.running = False  # reparented: the parent died without closing the pipe
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
                self.running = not self.frames.ended
                return
            count += 1
            tag = item[0]
            if tag == MSG:
                self.mailbox.inbox.append(item[1])
            elif tag == CALL:
                (self.urgent if item[2] == RUN_URGENT else self.calls).append(item[1:])
            elif tag == STOP:
                self.running = False

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

    def _flush(self) -> None:
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
            self.running = False

    def _call(self, method: str, args: tuple) -> Any:
        if method == RESET_STATS:
            return self.stats.reset()
        if method == SIM_TIME:
            return getattr(self.controller, "time", None)
        if method == LATE_IMPORTS:
            return sorted(set(sys.modules) - self.modules)
        return serve_call(self.controller, self.mailbox, method, args)

    def _reply(self, call_id: int, ok: bool, value: Any) -> None:
        try:
            self.conn.send((REPLY, call_id, ok, value))
        except (BrokenPipeError, ConnectionError, EOFError):
            self.running = False
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


def _shutdown(controller) -> None:
    """Leave the robot safe: disable, then destroy, whatever state we are in."""
    for name in ("disable", "destroy"):
        method = getattr(controller, name, None)
        if method is not None:
            try:
                method()
            except Exception:
                traceback.print_exc()


def child_main(factory: Callable[[Mailbox], Steppable], conn, stats: StatsRing,
               cycle_time: float | None, parent_pid: int, spin: float, guard: float,
               rt_priority: int | None, free: bool = False) -> None:
    """Entry point of the cycle process (see the module docstring)."""
    server: _Server | None = None

    def on_sigterm(*_):
        if server is None:
            raise SystemExit(1)  # still building: clean up on the way out
        server.running = False  # the loop ends after this cycle

    faulthandler.enable()   # a crash in native code (pybullet) leaves its stack on stderr
    # The parent may block signals in its threads (it waits for them with sigwait); a spawned
    # child inherits that mask, and must not: it has handlers of its own.
    signal.pthread_sigmask(signal.SIG_SETMASK, ())
    # Ctrl-C in a terminal reaches the whole process group; the parent decides when we stop.
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, on_sigterm)
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
        server = _Server(conn, controller, mailbox, stats, parent_pid, guard)
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
        server.async_task.wait(30.0)  # let a file being stored be finished
        _shutdown(controller)
        server._flush()
        conn.close()
    raise SystemExit(code)


def _fatal(conn, text: str) -> None:
    try:
        conn.send((FATAL, text))
    except Exception:
        pass
