"""Issue 30: bounded jerk everywhere, measured from outside as the issue measured it. Each test
records every cycle's commanded joint positions (the controller's recorder, or the feedback
ring, on the lock-step clock) and checks, at every cycle, the third difference over 4 ms cubed
against each joint's jerk limit (robot/arm.py max_jerk) and the second difference against its
acceleration limit, both with a relative tolerance of 1e-6: for planned moves (joint, straight,
arc, a blended path), stops, resumes and aborts, StopMotion at the set deceleration, the
safety stop of a lost lock holder, jogs and their stops, guarded moves into their force
settling and compliant moves. A hand-over between two modes is one more cycle among those
checked: positions, velocities and accelerations stay continuous across it."""
from __future__ import annotations

import threading
import time

import grpc
import numpy as np
import pytest

from landscape.server.cycle.feedback import CMD
from landscape.robot.units import matrix_rpy
from landscape.server.device.states import State
from landscape.v1 import motion_pb2, sensing_pb2, settings_pb2, types_pb2

from support import Arm, wait_until

DT = 0.004
TOL = 1e-6
JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
BASE = types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME
STRAIGHT = types_pb2.MOTION_TYPE_STRAIGHT_MOTION
HOME = [0.0, 0.3, 1.4, 0.0, 0.9, 0.0]


def ratios(positions: np.ndarray, arm) -> tuple[np.ndarray, np.ndarray]:
    """(6,) peak |third difference| / dt^3 over the jerk limit and |second difference| / dt^2
    over the acceleration limit, per joint, of commanded positions (K, 6), one per cycle."""
    model = arm.server.device.arm
    jerk = np.abs(np.diff(positions, 3, axis=0)).max(axis=0) / DT**3 / np.array(model.max_jerk)
    accel = (np.abs(np.diff(positions, 2, axis=0)).max(axis=0) / DT**2
             / np.array(model.max_acceleration))
    return jerk, accel


def assert_smooth(positions: np.ndarray, arm, what: str) -> None:
    jerk, accel = ratios(positions, arm)
    print(f"{what}: peak jerk / limit {np.round(jerk, 4)}, acceleration / limit "
          f"{np.round(accel, 4)}")
    assert jerk.max() <= 1 + TOL, (what, jerk)
    assert accel.max() <= 1 + TOL, (what, accel)


def recorded(arm, *commands) -> np.ndarray:
    """Every cycle's commanded joints (K, 6) while the commands run, each to its end."""
    arm.record_start()
    for command in commands:
        reply = command()
        if reply is not None and reply.ret_val.command_id:
            events = arm.wait_command(reply.ret_val.command_id)
            assert events[-1].event_id == "command_done", events[-1]
    _, data = arm.recorded_tips()
    return data["cmd_pos"]


def rows_since(arm, first: int) -> np.ndarray:
    ring = arm.server.link.feedback
    return np.array([ring.row(s) for s in range(first, ring.head + 1)])


def wait_simulated(arm, seconds: float) -> None:
    t0 = arm.server.device.feedback().time
    wait_until(lambda: arm.server.device.feedback().time >= t0 + seconds, timeout=20)


@pytest.fixture
def fast(tmp_path):
    """The kinematic backend: the arm follows its setpoints exactly, fast."""
    a = Arm(tmp_path, backend="kinematic")
    yield a
    a.close()


# ---- planned motion -------------------------------------------------------------------------

def full_speed(arm) -> None:
    arm.device.SetSpeed(settings_pb2.SetSpeedRequest(
        speed=100, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED), timeout=5)
    arm.device.SetAcceleration(settings_pb2.SetAccelerationRequest(
        accel=100, attribute=types_pb2.ACCEL_TYPE_PERCENT_ACCEL), timeout=5)


def test_joint_straight_and_arc_moves_keep_the_jerk_limit_every_cycle(fast):
    device = fast.device
    full_speed(fast)
    cmd = recorded(fast, lambda: device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        frame=JOINT, values=HOME)))
    assert_smooth(cmd, fast, "joint move")
    cmd = recorded(fast, lambda: device.MoveRelative(motion_pb2.MoveRelativeRequest(
        frame=BASE, values=[0.0, 0.2, -0.1, 0, 0, 0], motion_type=STRAIGHT)))
    assert_smooth(cmd, fast, "straight line")
    tip = fast.tool_tip()
    p0, rpy = tip[:3, 3], matrix_rpy(tip[:3, :3]).tolist()     # the tool's orientation kept
    cmd = recorded(fast, lambda: device.MoveArc(
        motion_pb2.MoveArcRequest(frame=BASE, offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA,
                                  arc_value=[*(p0 + [0.1, 0.1, 0.0]), *rpy],
                                  goal_value=[*(p0 + [0.2, 0.0, 0.0]), *rpy])))
    assert_smooth(cmd, fast, "arc")
    # The single joint move: 136 times the acceleration limit per second before.
    cmd = recorded(fast, lambda: device.MoveRelative(motion_pb2.MoveRelativeRequest(
        frame=JOINT, values=[1.5, 0, 0, 0, 0, 0])))
    assert_smooth(cmd, fast, "one joint")
    jerk, _ = ratios(cmd, fast)
    assert jerk[0] > 0.95       # the limit is what times it


def test_a_blended_path_at_full_speed_keeps_the_jerk_limit_every_cycle(fast):
    """The issue's case: a blended 20-point path at 100 % (joint 1 at 6,696 rad/s^3 before)."""
    full_speed(fast)
    rng = np.random.default_rng(5)
    points = [np.array(HOME)]
    for _ in range(19):
        points.append(np.clip(points[-1] + rng.normal(0.0, 0.25, 6), -1.2, 1.2))
    points = [p + np.array([0, 0, 1.0, 0, 0, 0]) * (p[2] < 0.3) for p in points]
    header = motion_pb2.PathHeader(path_name="blend", frame=JOINT,
                                   motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                   offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA,
                                   number_of_points=len(points))
    tags = [types_pb2.TagStruct(joint_values=p.tolist(), tag_name=f"p{i}")
            for i, p in enumerate(points)]
    fast.device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header, tags=tags)]),
                         timeout=30)
    cmd = recorded(fast, lambda: fast.device.PathMove(
        motion_pb2.PathMoveRequest(path_name="blend"), timeout=30))
    assert_smooth(cmd, fast, "blended path")


# ---- stops, resumes, aborts ------------------------------------------------------------------

def test_stops_resumes_and_an_abort_keep_the_jerk_limit_every_cycle(tmp_path):
    arm = Arm(tmp_path, pace=1.0, backend="kinematic")
    try:
        device = arm.device
        full_speed(arm)
        arm.record_start()
        reply = device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            frame=JOINT, values=[2.5, -0.5, 1.0, 1.0, 1.0, 2.0]))
        for pause in (0.15, 0.1, 0.2):
            wait_simulated(arm, pause)
            device.StopMotion(motion_pb2.StopMotionRequest())
            wait_simulated(arm, 0.05)
            device.ResumeMotion(motion_pb2.ResumeMotionRequest())
        wait_simulated(arm, 0.1)
        device.StopMotion(motion_pb2.StopMotionRequest())
        device.AbortMotion(motion_pb2.AbortMotionRequest())
        events = arm.wait_command(reply.ret_val.command_id, ("command_aborted",))
        assert [e.event_id for e in events].count("command_resumed") == 3
        _, data = arm.recorded_tips()
        assert_smooth(data["cmd_pos"], arm, "stops, resumes, abort")
    finally:
        arm.close()


def test_stop_motion_brakes_at_the_full_or_the_set_deceleration_as_asked(tmp_path):
    """Issue 30 item 3: StopMotion's deceleration is a setting: the arm's full one (unset, as
    before) or the one SetAcceleration set (STOP_DECELERATION_SET); bad values are refused."""
    arm = Arm(tmp_path, pace=1.0, backend="kinematic")
    try:
        device = arm.device
        full_speed(arm)
        device.SetAcceleration(settings_pb2.SetAccelerationRequest(
            accel=40, attribute=types_pb2.ACCEL_TYPE_PERCENT_ACCEL))
        set_limit = arm.server.device.settings.joint_accelerations
        peaks = {}
        for name, deceleration in (("full", None), ("set", motion_pb2.STOP_DECELERATION_SET),
                                   ("full, asked", motion_pb2.STOP_DECELERATION_FULL)):
            device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(frame=JOINT, values=HOME))
            wait_until(lambda: arm.server.device.state is State.RESTING, timeout=30)
            reply = device.MoveRelative(motion_pb2.MoveRelativeRequest(
                frame=JOINT, values=[2.5, 0, 0, 0, 0, 0]))
            wait_until(lambda: abs(arm.server.device.feedback().velocity[0]) > 2.5, timeout=20)
            first = arm.server.link.feedback.head
            request = (motion_pb2.StopMotionRequest() if deceleration is None
                       else motion_pb2.StopMotionRequest(deceleration=deceleration))
            device.StopMotion(request)
            cmd = rows_since(arm, first - 3)[:, CMD]
            assert_smooth(cmd, arm, f"stop at the {name} deceleration")
            peaks[name] = (np.abs(np.diff(cmd[:, 0], 2)).max() / DT**2) / set_limit[0]
            device.AbortMotion(motion_pb2.AbortMotionRequest())
            arm.wait_command(reply.ret_val.command_id, ("command_aborted",))
        print(f"peak deceleration / the set one: {peaks}")
        assert peaks["set"] <= 1 + TOL
        assert peaks["full"] > 2.0 and peaks["full, asked"] > 2.0     # 2.5 x the set one
        with pytest.raises(Exception, match="STOP_DECELERATION"):
            device.MoveRelative(motion_pb2.MoveRelativeRequest(
                frame=JOINT, values=[-0.5, 0, 0, 0, 0, 0]))
            device.StopMotion(motion_pb2.StopMotionRequest(
                deceleration=motion_pb2.STOP_DECELERATION_UNSPECIFIED))
    finally:
        arm.close()


def test_losing_the_lock_holder_stops_within_the_jerk_limit(tmp_path):
    """The disconnect handler's stop (a safety action): the arm's full deceleration, ramped."""
    arm = Arm(tmp_path, pace=1.0, backend="kinematic")
    try:
        full_speed(arm)
        arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            frame=JOINT, values=[3.0, 0, 1.5708, 0, 1.5708, 0]))
        wait_until(lambda: abs(arm.server.device.feedback().velocity[0]) > 2.0, timeout=20)
        first = arm.server.link.feedback.head - 3
        arm.session.close()
        wait_until(lambda: arm.server.device.state is State.UNLOCKED, timeout=10)
        cmd = rows_since(arm, first)[:, CMD]
        assert_smooth(cmd, arm, "lock holder lost")
        assert np.abs(np.diff(cmd[-3:, 0])).max() < 1e-12          # at rest
    finally:
        arm.close()


# ---- jog ---------------------------------------------------------------------------------------

@pytest.mark.physics
def test_a_jog_its_reversal_and_its_deadman_stop_keep_the_jerk_limit(tmp_path):
    arm = Arm(tmp_path, pace=1.0)
    try:
        arm.device.ManualControl(sensing_pb2.ManualControlRequest(
            type=sensing_pb2.MANUAL_CONTROL_TYPE_TEACHPENDANT), timeout=5)
        first = arm.server.link.feedback.head
        plan = [(types_pb2.REFERENCE_FRAME_JOINT_FRAME, [0, 0, 0, 0, 80, -80], 0.4),
                (types_pb2.REFERENCE_FRAME_JOINT_FRAME, [0, 0, 0, 0, -80, 80], 0.4),
                (BASE, [0, 60, 0, 0, 0, 0], 0.4)]

        def requests():
            for frame, velocity, seconds in plan:
                end = time.monotonic() + seconds
                while time.monotonic() < end:
                    yield sensing_pb2.JogRequest(deadman=True, frame=frame, velocity=velocity)
                    time.sleep(0.02)
            time.sleep(0.5)          # silence: the deadman stops the arm

        ended = []

        def drain(call):
            try:
                list(call)
            except grpc.RpcError as error:
                ended.append(error.code())

        threading.Thread(target=drain, args=(arm.device.Jog(requests(), timeout=30),),
                         daemon=True).start()
        wait_until(lambda: ended and arm.server.device.state is State.RESTING
                   and arm.server.link.feedback.head > first + 300, timeout=30)
        assert ended == [grpc.StatusCode.ABORTED]     # the deadman ended the session
        cmd = rows_since(arm, first)[:, CMD]
        assert np.ptp(cmd[:, 4]) > 0.1            # it did move
        assert_smooth(cmd, arm, "jogs and the deadman's stop")
    finally:
        arm.close()


# ---- guarded and compliant moves ---------------------------------------------------------------

TABLE_TOP = 0.2
FREE_SPOT = (0.65, 0.3)
Z = types_pb2.Vector3


# The force past the threshold a guarded move may reach, per approach speed (docs/motion.md).
PEAK_PAST = {100: 50.0, 300: 200.0}     # mm/s: N


@pytest.mark.physics
@pytest.mark.parametrize("mm_per_s", [100, 300])
def test_a_guarded_move_brakes_into_its_force_settling_continuously(tmp_path, mm_per_s):
    """The issue's case: down onto the table at 100 and 300 mm/s until fz reaches -20 N. The
    cycle where braking ends and force settling begins commanded joint 2 at 1.154 and 1.588
    times its acceleration limit; now every cycle, that one too, keeps the jerk and the
    acceleration limits (and the settling's end: it stopped its setpoints dead at 300 mm/s,
    1.09 times the jerk limit), and the done event reports the peak force past the threshold,
    within the documented bound."""
    arm = Arm(tmp_path)
    try:
        arm.get_tool("vacuum")
        arm.move_down_to(*FREE_SPOT, TABLE_TOP + 0.06)
        arm.record_start()
        reply = arm.device.MoveReact(sensing_pb2.MoveReactRequest(
            sensor_type="force_sensor", motion=Z(z=0.1), speed=mm_per_s / 20,
            thresholds=Z(z=-20.0)), timeout=30)
        events = arm.wait_command(reply.ret_val.command_id)
        _, data = arm.recorded_tips()
        message = events[-1].command.message
        print(f"{mm_per_s} mm/s: {message}")
        assert events[-1].event_id == "command_done" and message.startswith("triggered")
        peak = float(message.split("peak (")[1].split(")")[0].split(", ")[2])
        assert -20.0 - PEAK_PAST[mm_per_s] <= peak <= -20.0
        assert_smooth(data["cmd_pos"], arm, f"guarded move at {mm_per_s} mm/s")
    finally:
        arm.close()


@pytest.mark.physics
def test_a_compliant_slide_keeps_the_jerk_limit(tmp_path):
    arm = Arm(tmp_path)
    try:
        arm.get_tool("vacuum")
        arm.move_down_to(*FREE_SPOT, TABLE_TOP + 0.03)
        arm.record_start()
        reply = arm.device.MoveReact(sensing_pb2.MoveReactRequest(
            sensor_type="force_sensor", motion=Z(z=0.1), speed=0.1,
            thresholds=Z(z=-20.0)), timeout=30)
        arm.wait_command(reply.ret_val.command_id)
        reply = arm.device.Comply(sensing_pb2.ComplyRequest(
            sensor_type="force_sensor", thresholds=[0, 0, -20, 0, 0, 0], max_timeout=30,
            proportional_gains=[0, 0, 0.001, 0, 0, 0], compliance=Z(z=0.01),
            compliance_speed=1, motion=Z(x=0.05), speed=1), timeout=30)
        events = arm.wait_command(reply.ret_val.command_id)
        assert events[-1].event_id == "command_done", events[-1]
        _, data = arm.recorded_tips()
        assert_smooth(data["cmd_pos"], arm, "guarded touch, then a compliant slide")
    finally:
        arm.close()
