"""Issue 31 item 4: motion that starts in a cycle. On the lock-step clock, read on the feedback
ring (one row per cycle): the cycle that takes a run from the server already moves the arm."""
from __future__ import annotations

import itertools
import os
import signal
import threading

import numpy as np
import pytest

from landscape.server.cycle.feedback import CMD, WALL
from landscape.v1 import motion_pb2, types_pb2

from support import Arm, wait_until

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
HOME = [0.0, 0.3, 1.4, 0.0, 0.9, 0.0]
# rad: long_path's section (about 9 rad) is timed in chunks as it plays above this, as a
# section longer than path_planning.LONG_SECTION is in service
SECTION = 4.0


@pytest.fixture
def fast(tmp_path):
    """The kinematic backend: the arm follows its setpoints exactly, fast."""
    a = Arm(tmp_path, backend="kinematic")
    yield a
    a.close()


def reported(arm, op: str, field: str) -> list:
    """`field` of each of the executor's `op` reports from now on."""
    values: list = []
    device = arm.server.device
    original = device.on_cycle_message

    def spy(msg):
        if isinstance(msg, dict) and msg.get("op") == op:
            values.append(msg[field])
        original(msg)
    device.on_cycle_message = spy
    return values


def started_cycles(arm) -> list[float]:
    """The tick stamps of the cycles that took a run (the executor's "started" reports)."""
    return reported(arm, "started", "wall_time")


def marked(arm) -> list[int]:
    """The labels of the executor's "mark" reports from now on (a path's point indices)."""
    return reported(arm, "mark", "label")


def setpoint_step(arm, wall_time: float) -> float:
    """How far the setpoint moved on the cycle stamped `wall_time` (rad, the largest joint)."""
    ring = arm.server.link.feedback
    wait_until(lambda: ring.row(ring.head)[WALL] > wall_time)
    seq = ring.head
    while ring.row(seq)[WALL] > wall_time:
        seq -= 1
    assert ring.row(seq)[WALL] == wall_time
    return float(np.max(np.abs(ring.row(seq)[CMD] - ring.row(seq - 1)[CMD])))


def run(arm, call) -> None:
    reply = call()
    assert arm.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"


def at_first_point(arm, name: str, points: list, transition: float) -> list:
    """A blended joint path through `points` loaded as `name`, the arm moved to its first
    point; the points."""
    header = motion_pb2.PathHeader(path_name=name, frame=JOINT,
                                   motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                   offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)
    arm.device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header, tags=[
        types_pb2.TagStruct(joint_values=q, transition_speed=transition) for q in points])]),
        timeout=60)
    run(arm, lambda: arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        frame=JOINT, values=points[0]), timeout=30))
    return points


def long_path(arm, name: str, count: int) -> list:
    """A blended path of `count` joint points around HOME, loaded, the arm at its start."""
    return at_first_point(arm, name, [
        [0.4 * np.sin(i / 9), 0.3 + 0.15 * np.sin(i / 13), 1.4 + 0.1 * np.cos(i / 11),
         0.2 * np.sin(i / 7), 0.9, 0.0] for i in range(count)], 60)


def test_a_joint_move_and_a_path_from_its_first_point_move_on_the_cycle_that_takes_them(fast):
    at_first_point(fast, "ring", [[0.3 * np.sin(i / 5), 0.3 + 0.1 * np.sin(i / 7), 1.4, 0.0,
                                   0.9, 0.0] for i in range(12)], 40)
    stamps = started_cycles(fast)
    run(fast, lambda: fast.device.PathMove(motion_pb2.PathMoveRequest(path_name="ring"),
                                           timeout=30))
    run(fast, lambda: fast.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        frame=JOINT, values=HOME), timeout=30))
    assert len(stamps) == 2
    path_step, move_step = (setpoint_step(fast, stamp) for stamp in stamps)
    assert path_step > 0.0, "the path's first cycle held the arm where it was"
    assert move_step > 0.0, "the move's first cycle held the arm where it was"


def resting_away_from(ring, start, cycles: int = 10) -> bool:
    """Whether the newest `cycles` setpoints are one and the same, away from `start`."""
    head = ring.head
    rows = [ring.row(seq) for seq in range(head - cycles, head + 1)]
    if any(row is None for row in rows):
        return False
    setpoints = np.array([row[CMD] for row in rows])
    return (np.abs(setpoints - setpoints[-1]).max() < 1e-12
            and np.abs(setpoints[-1] - np.asarray(start)).max() > 1e-3)


def sent_to_cycle(arm) -> list[tuple[dict, np.ndarray]]:
    """The run and stretch messages the server sends the cycle, each with the newest cycle's
    setpoint when it was sent (where the arm was then)."""
    sent: list[tuple[dict, np.ndarray]] = []
    link = arm.server.device.motions.link
    original = link.send

    def spy(message):
        if isinstance(message, dict) and message.get("op") in ("run", "checked", "refused",
                                                                "append"):
            sent.append(({k: v for k, v in message.items() if k != "arrays"},
                         link.feedback.latest().command.copy()))
        original(message)
    link.send = spy
    return sent


def test_a_late_stretch_slows_the_arm_along_the_path_and_it_goes_on(fast):
    """The first later stretch is handed to the cycle only once the arm has stood still
    for it for 10 cycles (late, by the arm's own clock: so on a machine of any speed): the
    arm brakes to rest before the rows not yet timed and checked, and goes on when they come.
    Every cycle keeps the velocity, acceleration and jerk limits, and every setpoint lies on
    the timed path; the motion ends done at the last point."""
    from landscape.server.planning import path_planning
    points = long_path(fast, "late", 240)
    motions, runs = fast.server.device.motions, fast.server.device.path_runs
    planned = np.concatenate([t.positions for t, _ in path_planning.plan_run_lazily(
        motions.planner, runs.paths.get("late"), motions.planning_start(),
        fast.server.device.settings, 1, SECTION)])
    runs.time_ahead, runs.long_section = True, SECTION   # as on the real-time clock
    link, held = motions.link, []
    send = link.send

    def late(message):
        if isinstance(message, dict) and message.get("op") in ("append", "checked") \
                and not held:
            held.append(message["op"])
            wait_until(lambda: resting_away_from(link.feedback, points[0]), timeout=120)
        send(message)
    link.send = late
    fast.record_start()
    run(fast, lambda: fast.device.PathMove(motion_pb2.PathMoveRequest(path_name="late"),
                                           timeout=60))
    played_within_limits_resting_mid_path(fast, planned)
    assert np.allclose(fast.joints(), points[-1], atol=1e-4)


def test_a_long_path_starts_before_it_is_fully_timed(fast):
    """A path whose blended section is long (240 points) is timed as it plays: the run goes to
    the cycle with its first pieces, the later ones follow ("append", with how far the run is
    checked), and the arm has left its start when the last of them is sent. It ends done at
    the last point, having passed every point's mark in order."""
    points = long_path(fast, "long", 240)
    runs = fast.server.device.path_runs
    runs.time_ahead, runs.long_section = True, SECTION   # as on the real-time clock
    runs.check_ahead_delay = 0.05
    sent, marks = sent_to_cycle(fast), marked(fast)
    run(fast, lambda: fast.device.PathMove(motion_pb2.PathMoveRequest(path_name="long"),
                                           timeout=30))
    assert marks == list(range(len(points))), "the points' marks, each once, in order"
    (start, _), *later = sent
    assert start["op"] == "run"
    assert {m["op"] for m, _ in later} <= {"append", "checked"}
    assert [m["all"] for m, _ in later] == [False] * (len(later) - 1) + [True]
    appended = [where for m, where in later if m["op"] == "append"]
    assert appended, "every piece was timed before the run started"
    assert np.abs(appended[-1] - np.array(points[0])).max() > 1e-3, \
        "the arm had not left its start when the last piece was sent"
    assert np.allclose(fast.joints(), points[-1], atol=1e-4)


def test_a_section_under_the_long_section_is_timed_whole_before_its_run_starts(fast):
    """long_path's section (about 9 rad) is under path_planning.LONG_SECTION: timing it in
    chunks as it plays would start it later than timing it whole (the first chunk holds fewer
    rows than a stop may take plus the lead, so a second is timed before the start). Its run
    goes to the cycle with all its rows; it is still checked as it plays ("checked" only, no
    "append"), and ends done at the last point."""
    points = long_path(fast, "medium", 240)
    fast.server.device.path_runs.time_ahead = True   # as on the real-time clock
    sent = sent_to_cycle(fast)
    run(fast, lambda: fast.device.PathMove(motion_pb2.PathMoveRequest(path_name="medium"),
                                           timeout=30))
    (start, _), *later = sent
    assert start["op"] == "run" and start["checked"] > 0
    assert [m["op"] for m, _ in later] == ["checked"] * len(later)
    assert np.allclose(fast.joints(), points[-1], atol=1e-4)


def test_a_short_path_is_checked_whole_before_its_run_starts(fast):
    """A 100-point blended path of 1.3 s (bench_motion_start's) is timed whole in the start's
    planning job; checking the rest of its rows there costs about 2 us a row, so its run goes
    to the cycle checked whole (a collision anywhere in it is the call's error and nothing
    moved), and no stretch follows. Before, its run started on the 136 rows a stop may take
    plus the lead, and a second planning job checked the rest as it played."""
    points = at_first_point(fast, "short", [
        [0.3 * np.sin(i / 15), 0.2 * np.sin(i / 25), 1.5708 + 0.1 * np.cos(i / 20), 0.0,
         1.5708, 0.0] for i in range(100)], 40)
    fast.server.device.path_runs.time_ahead = True   # as on the real-time clock
    sent = sent_to_cycle(fast)
    run(fast, lambda: fast.device.PathMove(motion_pb2.PathMoveRequest(path_name="short"),
                                           timeout=30))
    assert [m["op"] for m, _ in sent] == ["run"]
    assert "checked" not in sent[0][0], "the run started on part of its rows checked"
    assert np.allclose(fast.joints(), points[-1], atol=1e-4)


@pytest.fixture
def paced(tmp_path):
    """The kinematic backend at the pace of the wall clock (a late planning process is late
    for the arm too; the recording keeps the whole run)."""
    a = Arm(tmp_path, backend="kinematic", pace=1.0)
    yield a
    a.close()


def test_a_path_timed_late_never_stops_dead(paced):
    """The planning process (a real one) stopped for 1.5 s (SIGSTOP) as a long path starts on
    its first timed pieces (about 1.5 s of play, 1 s before it brakes for them): the arm
    brakes to rest along the path before the rows not yet timed and goes on when they come.
    Every cycle keeps the velocity, acceleration and jerk limits, every setpoint lies on the
    timed path, and the motion ends done at the last point."""
    from landscape.server.planning import path_planning
    from landscape.server.planning.process import PlanningProcess
    points = long_path(paced, "late", 240)
    motions, runs = paced.server.device.motions, paced.server.device.path_runs
    planned = np.concatenate([t.positions for t, _ in path_planning.plan_run_lazily(
        motions.planner, runs.paths.get("late"), motions.planning_start(),
        paced.server.device.settings, 1, SECTION)])
    runs.planning = planning = PlanningProcess(motions.collisions, motions.planner.dt)
    runs.time_ahead, runs.long_section = True, SECTION   # as on the real-time clock
    link, resumed = motions.link, []
    send = link.send

    def stop_planning_as_the_run_starts(message):
        if isinstance(message, dict) and message.get("op") == "run" and not resumed:
            os.kill(planning.pid, signal.SIGSTOP)   # the next pieces are 1.5 s late
            resumed.append(threading.Timer(1.5, os.kill, (planning.pid, signal.SIGCONT)))
            resumed[0].start()
        send(message)
    link.send = stop_planning_as_the_run_starts
    paced.record_start()
    reply = paced.device.PathMove(motion_pb2.PathMoveRequest(path_name="late"), timeout=60)
    assert paced.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"
    played_within_limits_resting_mid_path(paced, planned)
    assert np.allclose(paced.joints(), points[-1], atol=1e-4)


@pytest.mark.parametrize("accel", [20, 50])
@pytest.mark.parametrize("checked", [0.3, 0.5, 0.7])
@pytest.mark.parametrize("late_by", [1, 4, 10, 40])
def test_rows_checked_while_the_arm_brakes_for_them_keep_it_within_the_limits(accel, checked,
                                                                              late_by):
    """The rest of a run checked (or timed: "append") `late_by` cycles after the play began
    to brake (at the arm's full limits) before the rows not checked: playback.Motion, as the
    executor plays it (the run at `accel` percent), stays within the arm's acceleration and
    jerk limits and goes on to the end. Found wiring the run timed as it plays: a resume planned in the middle of that stop
    ramp raised in the cycle (ruckig's -101, or an empty stretch in ramps.py)."""
    from landscape.robot.arm import arm_model
    from landscape.server.cycle.playback import Motion
    from landscape.server.planning.motion.timing import time_path
    from landscape.server.planning.motion.trajectory import Limits
    dt, arm = 0.004, arm_model()
    limits = Limits.scaled(arm, 100, accel)
    timed = time_path(np.array([[0.4 * np.sin(i / 9), 0.3 + 0.15 * np.sin(i / 13),
                                 1.4 + 0.1 * np.cos(i / 11), 0.2 * np.sin(i / 7), 0.9, 0.0]
                                for i in range(120)]), limits, dt)
    rows = len(timed.positions)
    motion = Motion({"id": "m", "acceleration": limits.acceleration, "jerk": limits.jerk,
                     "segments": [{"positions": timed.positions,
                                   "velocities": timed.velocities}],
                     "checked": int(rows * checked), "brake": 273}, dt)
    motion.stop_limit = np.array(arm.max_acceleration, dtype=float)   # as executor.py's
    motion.stop_jerk = np.array(arm.max_jerk, dtype=float)
    played, braking = [motion.position()] * 3, None
    for cycle in range(20 * rows):
        if braking is None and motion.awaiting:
            braking = cycle
        if braking is not None and cycle == braking + late_by:
            motion.checked_to(rows, True)
        motion.keep_to_checked()
        motion.advance()
        played.append(motion.position())
        if motion.s >= motion.last and not motion.next_segment():
            break
    else:
        raise AssertionError("the run did not end")
    played = np.array(played + [motion.position()] * 3)
    for order, limit in ((2, arm.max_acceleration), (3, arm.max_jerk)):
        peak = (np.abs(np.diff(played, order, axis=0)) / dt**order / np.array(limit)).max()
        assert peak <= 1 + 1e-6, (order, peak)
    assert np.allclose(played[-1], timed.positions[-1])

def played_within_limits_resting_mid_path(arm, planned: np.ndarray) -> None:
    """The recorded setpoints of a run that waited for late rows: every cycle within the
    velocity, acceleration and jerk limits; from its first move on, every setpoint within a
    hair of the chords of the `planned` samples (on the path); and at rest for at least 10
    cycles between its first and last move (it waited, and went on)."""
    cmd = arm.recorded_tips()[1]["cmd_pos"]
    model, dt = arm.server.device.arm, 0.004
    for order, limit in ((1, model.max_velocity), (2, model.max_acceleration),
                         (3, model.max_jerk)):
        peak = (np.abs(np.diff(cmd, order, axis=0)).max(axis=0) / dt**order / np.array(limit))
        assert peak.max() <= 1 + 1e-6, (order, peak)
    steps = np.linalg.norm(np.diff(cmd, axis=0), axis=1)
    moving = np.flatnonzero(steps > 1e-9)
    for q in cmd[moving[0] + 1:]:
        k = int(np.argmin(np.linalg.norm(planned - q, axis=1)))
        assert _on_chords(planned[max(k - 2, 0):k + 3], q, 1e-4), q
    middle = steps[moving[0]:moving[-1]]
    assert (middle < 1e-9).sum() >= 10, "the arm never waited for the late rows"


def _on_chords(near: np.ndarray, q: np.ndarray, tolerance: float) -> bool:
    """Whether q lies within `tolerance` (rad) of the chords between consecutive rows."""
    for a, b in itertools.pairwise(near):
        d = b - a
        t = np.clip(np.dot(q - a, d) / max(np.dot(d, d), 1e-30), 0.0, 1.0)
        if np.linalg.norm(a + t * d - q) < tolerance:
            return True
    return False
