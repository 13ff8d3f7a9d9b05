"""Paths parsed, loaded and planned in a process of their own, beside a server whose cycle runs
in one (issue 8.2).

Parsing a PathLoad stream (50 ms of Python per 10,000-point message), loading a long path
(resolving its points, timing every stretch, checking the whole run against the cell) or
planning its run keeps an interpreter busy for seconds. In the server's, a StopMotion
arriving meanwhile waited for that interpreter before its message could leave for the cycle:
p99 25 to 40 ms against 5.5 ms idle (bench_stop). The planning process has its own arm, its
own copy of the cell's collision scene, brought up to date by the first job after a change,
and the points of the PathLoad streams until their path is loaded; the server only hands it
each message's bytes as they came (services.RAW_REQUESTS), and its threads wait for answers
without holding the interpreter.

The jobs are plain functions of a PlanningContext, run here in the server when the cycle runs
in the server as well (the lock-step clock: a stop waits for the cycle's thread anyway).
One job at a time; a run's start at the server's niceness, the rest at +10. A planning
process that dies fails its job with Internal, is reported (the log, and `on_lost`: the
device's alarm), and another one starts at once. One whose server dies is killed by the
kernel at once, even in the middle of a job (lifeline.py).
"""
from __future__ import annotations

import itertools
import logging
import multiprocessing
import os
import signal
import threading
from collections import deque
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass, field
from typing import Callable, Iterator

import numpy as np
from google.protobuf.message import DecodeError

from landscape.server.planning import path_planning, run_check
from landscape.server.planning.collision import CheckResult, CollisionScene, check_motion
from landscape.server.api.convert import PathLoadStream
from landscape.server.errors import Collision, Internal, ParamError
from landscape.server.planning.moves import Planner
from landscape.server.planning.paths import StoredPath
from landscape.server.device.motion_settings import MotionSettings
from landscape.robot.units import Units
from landscape.server import lifeline
from landscape.robot.kinematics import Kinematics
from landscape.v1 import motion_pb2

log = logging.getLogger(__name__)
PROCESS_NAME = "lsc-planning"


# ---- the jobs ------------------------------------------------------------------------------

def check_run(scene: CollisionScene, trajectories: list, what: str = "the motion", *,
              allow=(), model=None) -> CheckResult:
    """Refuse trajectories (played back to back) that would bring two bodies of the cell
    within the safety margin (collision/); `allow` names contacts meant to happen (a guarded
    move's surface); `model`: what to check against (default: the scene as it is now). A
    piece that comes again (the cycles of a path run) is checked once. A refusal says where
    in the whole motion. Returns the counts of the check."""
    model = model or scene.model()
    samples = sum(len(t) for t in trajectories)
    checked: set[int] = set()
    first = configurations = pair_checks = bound_checks = 0
    for trajectory in trajectories:
        if id(trajectory) not in checked:
            checked.add(id(trajectory))
            result = check_motion(model, trajectory.positions, trajectory.dt, trajectory.marks,
                                  allow=allow)
            configurations += result.configurations
            pair_checks += result.pair_checks
            bound_checks += result.bound_checks
            if result.contact is not None:
                contact = result.contact.within(first, samples, trajectory.dt)
                raise Collision(f"{what} would collide: {contact}", **contact.metadata())
        first += len(trajectory)
    return CheckResult(None, configurations, pair_checks, bound_checks)


@dataclass
class PlanningContext:
    """What the jobs work with: the arm, the cell's collision scene, the open PathLoad
    streams and the runs being checked ahead, by key."""

    planner: Planner
    scene: CollisionScene
    streams: dict[str, PathLoadStream] = field(default_factory=dict)
    runs: dict[str, run_check.RunCheck] = field(default_factory=dict)   # checked ahead
    untimed: dict[str, "Untimed"] = field(default_factory=dict)   # runs timed as they play

    def stream(self, key: str) -> PathLoadStream:
        stream = self.streams.get(key)
        if stream is None:   # the planning process holding it ended, and another started
            raise Internal("this PathLoad stream was lost with the planning process that held "
                           "it; send the path again")
        return stream


@dataclass
class Untimed:
    """A run timed as it plays: its pieces not timed yet (plan_run_lazily), whether any are
    left, its rows checked so far, and the fastest speed of each joint timed so far (rad/s)."""

    pieces: Iterator
    more: bool = True
    checked: int = 0
    speed: np.ndarray = field(default_factory=lambda: np.zeros(6))


@dataclass(frozen=True)
class StreamRef:
    """The points of a PathLoad stream the planning context holds, for load_path."""

    key: str


def open_stream(ctx: PlanningContext, key: str, units: Units) -> None:
    ctx.streams[key] = PathLoadStream(units, path_planning.MAX_POINTS)


def feed_stream(ctx: PlanningContext, key: str, message) -> None:
    """One message of the stream (its bytes, or a PathLoadRequest), parsed and checked."""
    stream = ctx.stream(key)
    if isinstance(message, bytes):
        try:
            message = motion_pb2.PathLoadRequest.FromString(message)
        except DecodeError:
            raise ParamError(f"message {stream.messages} of the PathLoad stream is not a "
                             f"PathLoadRequest") from None
    stream.feed(message)


def finish_stream(ctx: PlanningContext, key: str):
    """(header, frame) of a stream that has ended; its points stay for load_path."""
    header, frame, _ = ctx.stream(key).finish()
    return header, frame


def load_path(ctx: PlanningContext, existing: StoredPath | None, name: str, frame,
              straight: bool, relative: bool, specs, settings: MotionSettings,
              outputs: set[str], q_start: np.ndarray, total: int | None
              ) -> tuple[StoredPath, int]:
    """Seed 3.5.1 pathLoad: the path with `specs` (PointSpecs, or a StreamRef to a stream's)
    resolved and appended, and the whole of it, as it would run from its first point, checked
    against the cell (a bad path is refused at load, naming the segment: the point it heads
    to). Returns the path and the number of points loaded."""
    if isinstance(specs, StreamRef):
        specs = ctx.stream(specs.key).specs
    planner = ctx.planner
    path = path_planning.load(planner, existing, name, frame, straight, relative, specs,
                              settings, outputs, q_start, total)
    check_run(ctx.scene, path_planning.plan_run(
        planner, path, np.array(path.points[0].joints), settings, 1), f"path {name!r}")
    return path, len(specs)


def plan_path_run(ctx: PlanningContext, path: StoredPath, q_start: np.ndarray,
                  settings: MotionSettings, cycles: int, what: str) -> list:
    """Seed 3.5.2 pathMove's trajectories from q_start, checked against the cell."""
    trajectories = path_planning.plan_run(ctx.planner, path, q_start, settings, cycles)
    check_run(ctx.scene, trajectories, what)
    return trajectories


def plan_path_lazily(ctx: PlanningContext, key: str, path: StoredPath, q_start: np.ndarray,
                     settings: MotionSettings, cycles: int, what: str, long_section: float
                     ) -> tuple[list, list, int, int, bool]:
    """plan_path_run for a run timed and checked as it plays (issue 31 item 4): its first
    pieces, timed until they hold enough rows to brake from their fastest plus run_check.LEAD
    (and up to STRETCH rows more once its first pass is timed), and those rows checked; the
    rest waits under `key` for next_pieces. `long_section` as in plan_run_lazily. Returns
    next_pieces' answer for all of them."""
    ctx.untimed[key] = Untimed(path_planning.plan_run_lazily(ctx.planner, path, q_start,
                                                             settings, cycles, long_section))
    ctx.runs[key] = run_check.RunCheck([], what)
    pieces, continues = [], []
    while True:
        untimed = ctx.untimed.get(key)
        brake = _brake_rows(ctx, untimed.speed) if untimed is not None else 0
        if untimed is None or untimed.checked >= brake + run_check.LEAD:
            break   # all of it is checked, or enough
        more, joins, checked, brake, everything = next_pieces(
            ctx, key, brake + run_check.LEAD - untimed.checked)
        pieces, continues = pieces + more, continues + joins
    if not everything and run_check.first_pass_timed(pieces, len(path.points) - 1):
        # Its first pass is timed: the rest costs little to time (the way back, cycles that
        # reuse its pieces), 2 us a row to check. A short run is checked whole before it starts.
        more, joins, checked, brake, everything = next_pieces(ctx, key, run_check.STRETCH)
        pieces, continues = pieces + more, continues + joins
    return pieces, continues, checked, brake, everything


def _brake_rows(ctx: PlanningContext, speed: np.ndarray) -> int:
    arm = ctx.planner.arm
    return run_check.brake_rows(speed, ctx.planner.dt, np.asarray(arm.max_acceleration),
                                np.asarray(arm.max_jerk))


def next_pieces(ctx: PlanningContext, key: str, rows: int
                ) -> tuple[list, list, int, int, bool]:
    """The next `rows` rows of a run plan_path_lazily started checked against the cell as it
    is now, and the pieces timed for them (none if they were timed already; a piece that
    `continues` the one before follows on from it, moving): (pieces, continues, rows checked
    so far, brake rows, all checked). The brake rows cover the fastest row timed so far
    (run_check.brake_rows): the arm plays only those. The run is forgotten once all is
    checked, or on a refusal."""
    run, untimed = ctx.runs.get(key), ctx.untimed.get(key)
    if run is None or untimed is None:   # the planning process holding it ended
        raise Internal("the rest of this run was lost with the planning process that held it")
    goal = untimed.checked + rows
    pieces, continues = [], []
    try:
        while untimed.more and run.rows + sum(len(p) for p in pieces) < goal:
            piece = next(untimed.pieces, None)
            if piece is None:
                untimed.more = False
            else:
                pieces.append(piece[0])
                continues.append(piece[1])
                untimed.speed = np.maximum(untimed.speed,
                                           np.max(np.abs(piece[0].velocities), axis=0))
        run.extend(pieces)
        stop = min(goal, run.rows)
        run.check(ctx.scene, untimed.checked, stop)
    except Exception:
        drop_run(ctx, key)
        raise
    untimed.checked = stop
    everything = not untimed.more and stop >= run.rows
    if everything:
        drop_run(ctx, key)
    return pieces, continues, stop, _brake_rows(ctx, untimed.speed), everything


def drop_run(ctx: PlanningContext, key: str) -> None:
    ctx.runs.pop(key, None)
    ctx.untimed.pop(key, None)


JOBS = {job.__name__: job for job in (open_stream, feed_stream, finish_stream, load_path,
                                      plan_path_run, plan_path_lazily, next_pieces, drop_run)}
# A run's start: a client waits for it with the arm at rest (no motion to stop), so it runs at
# the server's niceness; every other job is background work (_main).
STARTS = frozenset({"plan_path_run", "plan_path_lazily"})
_keys = itertools.count(1)


# ---- where they run --------------------------------------------------------------------------

class _Planning:
    """Where the jobs run: `run(job, *args)`; a PathLoad stream is opened, fed message by
    message, ended with the job "finish_stream" and dropped (`drop_stream` waits for
    nothing)."""

    def run(self, job: str, *args):
        raise NotImplementedError

    def open_stream(self, units: Units) -> str:
        key = f"stream-{next(_keys)}"
        self.run("open_stream", key, units)
        return key

    def feed_stream(self, key: str, message) -> None:
        self.run("feed_stream", key, message)


class InProcessPlanning(_Planning):
    """The jobs on the calling thread, with the server's planner and scene, one at a time (a
    path's later stretches are timed and checked on a thread of their own: run_check.follow)."""

    def __init__(self, planner: Planner, scene: CollisionScene):
        self.context = PlanningContext(planner, scene)
        self._lock = threading.Lock()

    def run(self, job: str, *args):
        with self._lock:
            return JOBS[job](self.context, *args)

    def drop_stream(self, key: str) -> None:
        self.context.streams.pop(key, None)

    def close(self) -> None:
        pass


class PlanningProcess(_Planning):
    """The jobs in a process of its own (spawned now, so that it is ready by the first job);
    `scene` is the server's, whose state goes with the first job after it changed. A
    stream's messages cross as the bytes they came in (services.RAW_REQUESTS)."""

    def __init__(self, scene: CollisionScene, cycle_time: float,
                 on_lost: Callable[[str], None] = lambda why: None):
        self.scene, self.cycle_time, self.on_lost = scene, cycle_time, on_lost
        self._lock = threading.Lock()
        self._closed = False
        self._dropped: deque[str] = deque()   # streams to forget, with the next job
        self._start()

    def _scene_state(self) -> tuple | None:
        """The scene's state if the planning process has not had it yet, else None."""
        if self.scene.version == self._sent_version:
            return None
        state = self.scene.state()
        self._sent_version = state[0]
        return state

    def _start(self) -> None:
        ctx = multiprocessing.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._process = ctx.Process(
            target=_main, args=(child, self.scene.cell, self.scene.margin, self.cycle_time,
                                os.getpid()),
            name="landscape-planning", daemon=True)
        lifeline.start(self._process)
        child.close()
        self._sent_version: int | None = None   # a new process starts from the cell

    @property
    def pid(self) -> int | None:
        return self._process.pid

    def run(self, job: str, *args):
        with self._lock:
            if self._closed:
                raise Internal("the planning process is closed")
            dropped = [self._dropped.popleft() for _ in range(len(self._dropped))]
            try:
                self._conn.send((job, self._scene_state(), args, dropped))
                ok, value = self._conn.recv()
            except (EOFError, OSError) as exc:
                self._process.join(1.0)
                why = f"the planning process ended (exit code {self._process.exitcode})"
                log.error("%s during %s: %r; starting another", why, job, exc)
                self._conn.close()
                self._start()
                self.on_lost(f"{why} while planning ({job}); another one has started")
                raise Internal(f"{why}; nothing was planned, and another one has started") \
                    from None
        if not ok:
            raise value
        return value

    def drop_stream(self, key: str) -> None:
        self._dropped.append(key)

    def close(self) -> None:
        with self._lock:
            self._closed = True
            self._conn.close()   # the process sees the end of its pipe and leaves
        self._process.join(5.0)
        if self._process.is_alive():
            self._process.kill()
            self._process.join(1.0)


def _main(conn, cell, margin: float, cycle_time: float, parent_pid: int) -> None:
    # Killed with the server, even in the middle of a job (it has nothing to leave safe).
    lifeline.bind_to_parent(parent_pid, signal.SIGKILL)
    # The server decides when this process ends (its pipe closes): not Ctrl-C in a terminal,
    # and a mask of blocked signals inherited from the server's threads is dropped.
    signal.pthread_sigmask(signal.SIG_SETMASK, ())
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:   # its name in ps and top (and for bench_soak, which measures it)
        with open("/proc/self/comm", "w") as comm:
            comm.write(PROCESS_NAME)
    except OSError:
        pass
    context = PlanningContext(Planner(Kinematics(cell.arm), cycle_time),
                              CollisionScene(cell, margin))
    # Background work (loads, stretches timed ahead of a moving arm) on a thread at niceness
    # +10: on a busy machine the server's command handling (a stop on its way to the cycle)
    # goes first. A start (STARTS) at the server's: at +10 a busy core held one for tens to
    # hundreds of ms (docs/motion.md).
    # (Linux: nice(2) sets the calling thread's niceness, not its process's.)
    background = ThreadPoolExecutor(1, initializer=os.nice, initargs=(10,))
    while True:
        try:
            job, state, args, dropped = conn.recv()
        except (EOFError, OSError):
            return
        for key in dropped:
            context.streams.pop(key, None)
        answer = (_answer(context, job, state, args) if job in STARTS else
                  background.submit(_answer, context, job, state, args).result())
        try:
            conn.send(answer)
        except (EOFError, OSError):
            return
        except Exception as exc:   # the answer did not pickle
            conn.send((False, Internal(f"planning's answer did not reach the server: {exc!r}")))


def _answer(context: PlanningContext, job: str, state, args) -> tuple[bool, object]:
    try:   # a refusal (CommandError) goes back as it is
        if state is not None:
            context.scene.restore(state)
        return True, JOBS[job](context, *args)
    except Exception as exc:
        return False, exc
