"""Stops that stop (issue 17): StopMotion, AbortMotion, the e-stop and the disconnect handler
each bring the arm to rest within the braking distance its limits allow, measured in the
physics; after any of them, and after re-activation, the first setpoint is where the arm is.
AbortMotion is valid once the arm is stopped (seed 3.6.2, Paused): from rest, its braking
distance is nil, and it must not move the arm at all.

The lock-step clock is held at a chosen cycle of a full-speed move, the stop is put in the
cycle's way, and the clock let go: the stop acts in the next cycle, as it would if it had
arrived during the held one. Braking distance along the path: from velocity v (rad/s per
joint), the fastest stop that keeps every joint within its acceleration a takes
T = max(|v| / a) and moves each joint |v| T / 2; the stop is allowed one cycle to arrive and
the following error it started with.
"""
from __future__ import annotations

import numpy as np
import pytest

from landscape.server.device.states import State
from landscape.robot.controller import operate_panel
from landscape.robot.controller import EnableState
from landscape.v1 import control_pb2, motion_pb2, settings_pb2, types_pb2

from reliability_support import RowLog, columns
from support import Arm, activate, locked_session, stubs, wait_until

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
START = [-1.2, -0.2, 1.9, 0.4, 1.1, -0.5]
GOAL = [1.3, 0.3, 1.4, -0.8, 0.7, 1.2]
PACE = 4.0          # simulated s per wall s: the row log reads every cycle
SETTLE = 1e-5       # rad: "at rest where the command says" (executor.SETTLE_POSITION)
AT_REST = {"stop": State.PAUSED, "abort": State.RESTING, "estop": State.ERROR,
           "disconnect": State.UNLOCKED}


@pytest.fixture
def arm(tmp_path):
    a = Arm(tmp_path, pace=PACE)
    a.device.SetSpeed(settings_pb2.SetSpeedRequest(
        speed=100, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED), timeout=5)
    a.device.SetAcceleration(settings_pb2.SetAccelerationRequest(
        accel=100, attribute=types_pb2.ACCEL_TYPE_PERCENT_ACCEL), timeout=5)
    reply = a.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(frame=JOINT, values=START))
    assert a.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"
    yield a
    a.close()


def _stop(arm, how: str):
    """At full speed towards GOAL, stop `how`; returns (the held cycle's sample, every row
    from the next cycle until the arm is at rest)."""
    clock, device = arm.server.link.clock, arm.server.device
    arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(frame=JOINT, values=GOAL))
    wait_until(lambda: device.state is State.MOVING)
    clock.hold_at(device.feedback().time + 0.4)
    wait_until(lambda: clock.held)
    before = device.feedback()
    log = RowLog(arm.server.link.feedback)
    calls = []
    if how in ("stop", "abort"):
        calls.append(arm.device.StopMotion.future(motion_pb2.StopMotionRequest(), timeout=10))
    elif how == "estop":
        arm.link.between_cycles(operate_panel, "press_estop")
    else:
        arm.session.close()
    if how != "estop":
        wait_until(lambda: clock.pending > 0)   # the stop waits for the next cycle
    clock.release()
    for call in calls:
        call.result()
    if how == "abort":   # from rest, where the stop left it
        wait_until(lambda: device.state is State.PAUSED)
        log.close()
        before = device.feedback()
        log = RowLog(arm.server.link.feedback)
        arm.device.AbortMotion(motion_pb2.AbortMotionRequest(), timeout=10)
    wait_until(lambda: device.state is AT_REST[how]
               and np.max(np.abs(device.feedback().velocity)) < 1e-3, timeout=10)
    if how == "disconnect":
        wait_until(lambda: device.feedback().enable is EnableState.DISABLED)
    return before, columns(log.close())


@pytest.mark.parametrize("how", ["stop", "abort", "estop", "disconnect"])
def test_a_stop_comes_to_rest_within_the_braking_distance(arm, how):
    limits = np.asarray(arm.server.device.arm.max_acceleration)
    before, rows = _stop(arm, how)
    v = np.abs(before.velocity)
    braking = v * np.max(v / limits) / 2
    bound = braking + v * arm.server.link.cycle_time + np.abs(before.command - before.position)
    travel = np.max(np.abs(rows["q"] - before.position), axis=0)
    print(f"{how}: speed {np.round(v, 3)} rad/s, travel {np.round(travel, 4)} rad, "
          f"braking distance {np.round(braking, 4)} rad")
    assert np.all(travel <= bound + 1e-4), (travel, bound)
    if how != "estop":   # braking along the path: the arm stays on the joint-space line
        line = np.array(GOAL) - np.array(START)
        off = rows["q"] - np.array(START)
        across = off - np.outer(off @ line, line) / (line @ line)
        assert np.max(np.linalg.norm(across, axis=1)) < 1e-3
    _check_first_setpoints(arm, how, rows)


def _check_first_setpoints(arm, how, rows):
    """At rest the setpoint is where the arm is; after re-activation the first enabled cycle
    commands where the arm is; the next motion starts there."""
    device = arm.server.device
    if how in ("stop", "abort"):
        assert np.max(np.abs(rows["cmd"][-1] - rows["q"][-1])) < SETTLE
    if how == "stop":
        arm.device.AbortMotion(motion_pb2.AbortMotionRequest(), timeout=10)
    log = RowLog(arm.server.link.feedback)
    if how == "estop":
        arm.link.between_cycles(operate_panel, "release_estop")
        wait_until(lambda: not device.status().estop)
        arm.device.Reset(control_pb2.ResetRequest(), timeout=10)
        activate(arm.session)
    elif how == "disconnect":
        arm.session = locked_session(arm.server)
        arm.device = stubs(arm.session.channel)[0]
        activate(arm.session)
    reply = arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(frame=JOINT, values=START))
    assert arm.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"
    after = columns(log.close())
    enabled = np.flatnonzero(after["enable"] == EnableState.ENABLED.value)
    first = enabled[0]
    if how in ("estop", "disconnect"):   # re-activated: disabled before, enabled from `first`
        assert first > 0
        assert np.max(np.abs(after["cmd"][first] - after["q"][first])) < SETTLE
    else:
        # Held since the stop: the setpoint it came to rest at (where the arm was, above). Not
        # the arm's position now: braked from 6.3 rad/s, a joint still sways about 1e-5 rad
        # around its setpoint (a busy machine's AbortMotion met such a moment).
        assert np.max(np.abs(after["cmd"][first] - rows["cmd"][-1])) < 1e-9
