"""Paths from load to run (seed 3.5): resolve loaded points to joints, plan a pathMove.

Loading resolves each point to a joint target, in order, starting from the path's last point
(or, for a new path, from where the arm is): Cartesian points by inverse kinematics in the
configuration of the point before, straight segments checked along their whole length. RELATIVE
data are offsets from the point before, resolved at load time. A point that fails names its
index in the load.

Running plans, for each cycle, a joint move from where the arm is to the first point (the
approach; from the last point for later cycles), then the points. The arm stops at the last
point and at every point whose transition speed is 0 or that has a dwell; it passes through the
others on a blended path. A point's speed and acceleration (percent; 0 keeps the set one) apply
to the stretch that ends at the next stop (the lowest there wins). Dwells are held setpoints.

A blended point is passed at its transition speed, a percent of the arm's maximum (seed 3.5.1;
types.proto TagStruct), held for a cycle either side of it: on a joint path, the fastest
joint's speed against its own maximum velocity (joints reaching their limits at different
speeds, the one nearest its limit sets the pace); on a straight path, the tool tip's linear
speed against the arm's maximum linear speed. Where the path or the set limits do not allow
that speed (too short a stretch to reach it, or above the set speed), the arm passes as fast
as they allow.
"""
from __future__ import annotations

import math
from collections.abc import Iterator
from dataclasses import dataclass, replace

import numpy as np

from landscape.server.planning import aux_commands
from landscape.server.errors import CommandError, OutOfRange, ParamError, Unreachable
from landscape.server.planning.motion.cartesian import straight_path, tool_pose
from landscape.server.planning.motion.timing import duration_lower_bound
from landscape.server.planning.motion.trajectory import PlanningError, Trajectory
from landscape.server.planning.moves import Planner, check_duration
from landscape.server.planning.paths import PathPoint, StoredPath
from landscape.server.device.motion_settings import MAX_MOTION_SECONDS, MIN_PERCENT, MotionSettings
from landscape.server.planning.targets import Frame, check_joints, check_pose_values, goal_tip

MAX_CYCLES = 10_000
MAX_POINTS = 100_000    # per path: a bound on what one client can make the server keep
# rad of joint path: a stretch between stops longer than this is timed in stretches by
# plan_run_lazily. Timed so, a run starts on two chunks (the first holds fewer rows than a
# stop may take plus run_check.LEAD) and two planning jobs; timing whole grows with the
# length, and starts later than that only past about 20 rad (docs/motion.md).
LONG_SECTION = 20.0


@dataclass(frozen=True)
class PointSpec:
    """A loaded tag_struct in SI: values are joints (rad) or x, y, z (m), roll, pitch, yaw (rad)."""

    values: np.ndarray
    tag_name: str = ""
    tag_index: int = 0
    time_delay: float = 0.0
    transition_speed: float = 0.0
    speed: float = 0.0
    accel: float = 0.0
    aux_commands: tuple[str, ...] = ()


def at_point(index: int, error: CommandError) -> CommandError:
    """The same error, naming the point it is about."""
    error.message = f"point {index}: {error.message}"
    error.args = (error.message,)
    error.metadata["index"] = str(index)
    return error


def _check_numbers(spec: PointSpec) -> None:
    if not np.all(np.isfinite([spec.time_delay, spec.transition_speed, spec.speed, spec.accel])):
        raise ParamError("time delay and speeds must be finite")
    if not 0 <= spec.time_delay <= MAX_MOTION_SECONDS:
        raise OutOfRange(f"time delay {spec.time_delay:g} s is not from 0 to "
                         f"{MAX_MOTION_SECONDS:g} s", field="time_delay",
                         maximum=f"{MAX_MOTION_SECONDS:g} s")
    for name in ("transition_speed", "speed", "accel"):
        if not 0 <= getattr(spec, name) <= 100:
            raise OutOfRange(f"{name} {getattr(spec, name):g} is not a percent (0 to 100)",
                             field=name, maximum="100 %")
    for name in ("speed", "accel"):   # 0 keeps the set one; a tiny one is refused
        if 0 < getattr(spec, name) < MIN_PERCENT:
            raise OutOfRange(f"{name} {getattr(spec, name):g} % is below {MIN_PERCENT:g} % "
                             "(0 keeps the set one)", field=name, minimum=f"{MIN_PERCENT:g} %")


def load(planner: Planner, existing: StoredPath | None, name: str, frame: Frame, straight: bool,
         relative: bool, specs: list[PointSpec], settings: MotionSettings, outputs: set[str],
         q_start: np.ndarray, total: int | None = None) -> StoredPath:
    """Seed 3.5.1 pathLoad: `existing` (or a new path) with `specs` appended, every point
    resolved and checked; raises naming the first bad point. q_start: where a new path starts
    from (rad). total: the point count the client announced, if any."""
    if not name:
        raise ParamError("a path needs a name")
    if not specs:
        raise ParamError(f"the PathLoad stream for {name!r} carried a header and no points: "
                         f"send at least one tag")
    if total is not None and total != len(specs):
        raise ParamError(f"number_of_points says {total}, the stream carried {len(specs)}")
    path = existing or StoredPath(name, straight, tuple(settings.tool_offset.ravel()))
    if path.straight != straight:
        raise ParamError(f"path {name!r} holds {'straight' if path.straight else 'joint'} "
                         f"motion; load the same motion type or clear it first")
    if len(path.points) + len(specs) > MAX_POINTS:
        raise OutOfRange(f"path {name!r} would hold more than {MAX_POINTS} points")
    q_prev = np.array(path.points[-1].joints) if path.points else q_start
    return path.appended(resolve(planner, path, q_prev, frame, relative, specs, settings, outputs,
                                 first_index=len(path.points)))


def resolve(planner: Planner, path: StoredPath, q_prev: np.ndarray, frame: Frame, relative: bool,
            specs: list[PointSpec], settings: MotionSettings, outputs: set[str],
            first_index: int = 0) -> list[PathPoint]:
    """Joint targets for `specs`, appended after `q_prev` (rad); raises naming the bad index."""
    kin, tcp = planner.kinematics, path.tcp_matrix
    points = []
    for index, spec in enumerate(specs, start=first_index):
        try:
            _check_numbers(spec)
            for command in spec.aux_commands:
                aux_commands.parse(command, outputs)
            if frame is Frame.JOINT:
                q = check_joints(planner.arm, q_prev + spec.values if relative else spec.values)
                tip = kin.forward(q) @ tcp
            else:
                tip = goal_tip(frame, check_pose_values(spec.values, "tags"), relative,
                               kin.forward(q_prev) @ tcp, settings)
                q = planner.pose_goal_joints(q_prev, tip @ np.linalg.inv(tcp), "tags")
            if path.straight and (points or path.points):   # the approach is a joint move
                try:
                    q = straight_path(kin, q_prev, [tip], tcp=tcp)[0][-1]
                except PlanningError as error:
                    raise Unreachable(str(error), reason_code=str(error.reason),
                                      fraction=f"{error.fraction or 0:.4f}") from None
        except CommandError as error:
            raise at_point(index, error) from None
        points.append(PathPoint(tuple(float(v) for v in q), spec.tag_name, spec.tag_index,
                                spec.time_delay, spec.transition_speed, spec.speed, spec.accel,
                                tuple(spec.aux_commands)))
        q_prev = q
    return points


def plan_run(planner: Planner, path: StoredPath, q_start: np.ndarray, settings: MotionSettings,
             cycles: int) -> list[Trajectory]:
    """Trajectories for `cycles` passes of the path (0: one dry pass); their marks are labelled
    with point indices. Later cycles reuse the first cycle's arrays.

    One pass (its approach, the points and their dwells) lasts at most MAX_MOTION_SECONDS: a
    cheap lower bound refuses a longer one before anything is planned (OutOfRange naming the
    speed, the acceleration or the time delay), and every piece is planned within what is
    left."""
    return [piece for piece, _ in plan_run_lazily(planner, path, q_start, settings, cycles,
                                                  long_section=math.inf)]


def plan_run_lazily(planner: Planner, path: StoredPath, q_start: np.ndarray,
                    settings: MotionSettings, cycles: int, long_section: float = LONG_SECTION
                    ) -> Iterator[tuple[Trajectory, bool]]:
    """plan_run's trajectories as (trajectory, continues) pairs, each timed when asked for; a
    stretch between stops longer than `long_section` (rad of joint path) comes in chunks as
    time_in_stretches gives them out (issue 31 item 4), each but the first `continues` the
    one before (its rows follow on, the arm moving: one segment for the cycle). The refusals
    before anything is planned are raised by this call; a later chunk may still raise a
    CommandError (the rows before it stay valid)."""
    if not path.points:
        raise ParamError(f"path {path.name!r} has no points")
    if not 0 <= cycles <= MAX_CYCLES:
        raise OutOfRange(f"number of cycles must be 0 to {MAX_CYCLES}, got {cycles}")
    last = np.array(path.points[-1].joints)
    stretches = _stretches(planner, path, settings)
    _check_pass(planner, path, settings, stretches, [q_start, last] if cycles > 1 else [q_start])
    return _run(planner, path, q_start, settings, cycles, stretches, long_section)


def _run(planner, path, q_start, settings, cycles: int, stretches, long_section: float):
    first, last = np.array(path.points[0].joints), np.array(path.points[-1].joints)
    approach = _approach(planner, q_start, first, settings, MAX_MOTION_SECONDS)
    yield from ((piece, False) for piece in approach)
    body = []
    for piece in _plan_points(planner, path, stretches, MAX_MOTION_SECONDS - _seconds(approach),
                              long_section):
        body.append(piece)
        yield piece
    if cycles > 1:
        back = _approach(planner, last, first, settings,
                         MAX_MOTION_SECONDS - _seconds([p for p, _ in body]))
        for _ in range(cycles - 1):
            yield from ((piece, False) for piece in back)
            yield from body


def _seconds(pieces: list[Trajectory]) -> float:
    return sum(piece.duration for piece in pieces)


def _approach(planner: Planner, q_from: np.ndarray, q_to: np.ndarray, settings,
              max_duration: float) -> list[Trajectory]:
    if np.max(np.abs(q_from - q_to)) < 1e-9:
        return []
    move = planner.joint_move(q_from, q_to, planner.limits(settings, None), max_duration)
    return [Trajectory(move.dt, move.positions, move.velocities)]   # no marks: no points here


def _stretches(planner: Planner, path: StoredPath, settings: MotionSettings) -> list[tuple]:
    """(first point index, last point index, Limits) of each stretch between stops: a point's
    speed and acceleration (percent, 0: the set one) apply to the stretch ending at the next
    stop, the lowest there winning."""
    points, out, start = path.points, [], 0
    for end in range(1, len(points)):
        if not (points[end].stops or end == len(points) - 1):
            continue
        speeds = [p.speed for p in points[start + 1:end + 1] if p.speed > 0]
        accels = [p.accel for p in points[start + 1:end + 1] if p.accel > 0]
        limits = planner.limits(settings.with_accel_percent(min(accels)) if accels else settings,
                                min(speeds) if speeds else None)
        out.append((start, end, limits))
        start = end
    return out


def _check_pass(planner: Planner, path: StoredPath, settings: MotionSettings, stretches,
                approach_from: list[np.ndarray]) -> None:
    """OutOfRange if one pass cannot last MAX_MOTION_SECONDS or less, by a cheap lower bound."""
    dwells = sum(p.time_delay for p in path.points)
    if dwells > MAX_MOTION_SECONDS:
        raise OutOfRange(f"the time delays of path {path.name!r} add up to {dwells:.4g} s; a "
                         f"pass lasts at most {MAX_MOTION_SECONDS:g} s", field="time_delay",
                         maximum=f"{MAX_MOTION_SECONDS:g} s")
    joints = np.array([p.joints for p in path.points])
    before = dwells
    for start, end, limits in stretches:
        tool = tool_pose(planner.kinematics, path.tcp_matrix) if path.straight else None
        check_duration(joints[start:end + 1], limits, MAX_MOTION_SECONDS, tool_path=tool,
                       before=before)
        before += duration_lower_bound(joints[start:end + 1], limits, tool_path=tool)[0]
    limits = planner.limits(settings, None)
    for q in approach_from:
        check_duration(np.array([q, joints[0]]), limits, MAX_MOTION_SECONDS, before=before)


def _plan_points(planner: Planner, path: StoredPath, stretches, max_duration: float,
                 long_section: float) -> Iterator[tuple[Trajectory, bool]]:
    """From point 0 through the last point, dwells included, as (trajectory, continues)
    pairs (plan_run_lazily); marks labelled by point index; the whole within max_duration (s)."""
    points = path.points
    # Point 0 is reached by the approach: its mark sits on a hold there if it has a dwell (or
    # is the only point), else on the first stretch's first sample: a hold of its own would
    # cost the run's first cycle (it moves on the cycle that takes it).
    held = points[0].time_delay > 0 or not stretches
    if held:
        yield _hold(planner.dt, points[0].joints, points[0].time_delay, mark=0), False
    marked = held
    left = max_duration - sum(p.time_delay for p in points)
    for start, end, limits in stretches:
        for k, piece in enumerate(_time_stretch(planner, path, points[start:end + 1], limits,
                                                start, left, long_section)):
            if not marked:
                piece, marked = replace(piece, marks=((0, 0), *piece.marks)), True
            yield piece, k > 0
            left -= piece.duration
        if points[end].time_delay > 0:
            yield _hold(planner.dt, points[end].joints, points[end].time_delay), False


def _time_stretch(planner: Planner, path: StoredPath, stretch, limits, first_label: int,
                  max_duration: float, long_section: float) -> Iterator[Trajectory]:
    """The stretch's trajectory, or its chunks if it is longer than long_section (rad)."""
    joints = np.array([p.joints for p in stretch])
    kin, tcp = planner.kinematics, path.tcp_matrix
    try:
        if path.straight:
            dense, rows = straight_path(kin, joints[0], [kin.forward(q) @ tcp for q in joints[1:]],
                                        tcp=tcp)
            row_of = [0, *(int(row) for row in rows)]   # the dense row of each point
        else:
            dense, row_of = joints, list(range(len(joints)))
        label_of = {row: first_label + i for i, row in enumerate(row_of) if i > 0}
        # The points between the stretch's ends are passed at their transition speed.
        passing = {row_of[i]: p.transition_speed / 100.0 for i, p in enumerate(stretch)
                   if 0 < i < len(stretch) - 1}
    except PlanningError as error:
        raise Unreachable(f"path {path.name!r}: {error}", reason_code=str(error.reason)) from None
    tool = tool_pose(kin, tcp) if path.straight else None
    try:
        if np.sum(np.linalg.norm(np.diff(dense, axis=0), axis=1)) > long_section:
            given = 0   # rows of the stretch in the chunks before
            for chunk in planner.timed_in_stretches(dense, limits, tool, pass_speeds=passing):
                yield _labelled(planner.dt, chunk.positions, chunk.velocities,
                                [(row - given, w) for row, w in chunk.marks], label_of)
                given += len(chunk.positions)
            return
        timed = planner.timed(dense, limits, tool, max_duration=max_duration,
                              pass_speeds=passing)
    except CommandError as error:
        error.message = f"path {path.name!r}: {error.message}"
        error.args = (error.message,)
        raise
    yield _labelled(timed.dt, timed.positions, timed.velocities, timed.marks, label_of)


def _labelled(dt: float, positions, velocities, marks, label_of: dict) -> Trajectory:
    """A trajectory with its marks (sample, dense row) labelled by point index; the first
    point of a stretch was marked by the stretch before, dense rows carry no mark."""
    return Trajectory(dt, positions, velocities,
                      tuple((sample, label_of[w]) for sample, w in marks if w in label_of))


def _hold(dt: float, joints, seconds: float, mark: int | None = None) -> Trajectory:
    """A held setpoint: `seconds` of dwell (at least one sample)."""
    samples = max(1, round(seconds / dt)) + (1 if seconds > 0 else 0)
    positions = np.repeat(np.array(joints)[None], samples, axis=0)
    return Trajectory(dt, positions, np.zeros_like(positions),
                      () if mark is None else ((0, mark),))
