"""Jog integration on its own (jog_control.py): the line a Cartesian jog keeps, the limits,
the deadman and the joint ranges, cycle by cycle without a controller."""
from __future__ import annotations

import math

import numpy as np
import pytest

from landscape.server.cycle.jog_integrator import (HEADROOM, MANUAL_TIP_SPEED, STALE_CYCLES,
                                                   JogIntegrator,
                                          JogLimits)
from landscape.server.cycle.tip_model import TipModel
from landscape.robot.arm import arm_model

DT = 0.004
ARM = arm_model()
START = np.array([0.0, 0.0, math.pi / 2, 0.0, math.pi / 2, 0.0])


def _jog(deadman_cycles: int = 50, guarded: bool = False) -> JogIntegrator:
    a = np.array(ARM.max_acceleration)
    cartesian = np.array([ARM.max_linear_acceleration, ARM.max_angular_acceleration])
    limits = JogLimits(np.array(ARM.max_velocity) * 0.25, a * 0.5, a, ARM.lower, ARM.upper,
                       cartesian * 0.5, cartesian, MANUAL_TIP_SPEED, deadman_cycles,
                       np.array(ARM.max_jerk) * 0.5, np.array(ARM.max_jerk))
    return JogIntegrator("j", START, limits, TipModel(ARM), np.eye(4), DT, guarded=guarded)


def _request(frame: str, velocity, deadman: bool = True) -> dict:
    return {"frame": frame, "velocity": np.asarray(velocity, dtype=float), "deadman": deadman}


def test_a_cartesian_jog_keeps_its_line_and_orientation_at_the_manual_speed():
    jog, tip = _jog(), TipModel(ARM)
    start = tip.forward(START).copy()
    previous = start[:3, 3].copy()
    speeds = []
    for _ in range(300):
        jog.command(_request("base", [0.3, 0.2, 0.0, 0, 0, 0]))   # asks 0.36 m/s
        q, _ = jog.step()
        now = tip.forward(q)
        speeds.append(np.linalg.norm(now[:3, 3] - previous) / DT)
        previous = now[:3, 3].copy()
    moved = now[:3, 3] - start[:3, 3]
    direction = np.array([0.3, 0.2, 0.0]) / np.linalg.norm([0.3, 0.2, 0.0])
    off_line = moved - (moved @ direction) * direction
    assert np.linalg.norm(off_line) < 5e-5 * np.linalg.norm(moved) / 0.05   # 50 um per 5 cm
    # The joints follow the jog through a jerk-limited tracker (issue 30), a cycle or two
    # behind the line's own correction: the tool turns by 0.1 mrad at most.
    assert np.allclose(now[:3, :3], start[:3, :3], atol=1e-4)
    assert max(speeds) <= MANUAL_TIP_SPEED * (1 + 1e-3)   # a chord of the step, not J qd
    assert speeds[-1] == pytest.approx(HEADROOM * MANUAL_TIP_SPEED, rel=1e-3)   # the headroom


def test_a_cartesian_jog_that_ends_comes_to_rest_on_its_line():
    """The joints follow the twist's jerk-limited braking a little behind (issue 30), so the
    tip leaves the line while the jog stops; it ended 0.27 mm off it, the tool turned by
    6 mrad, once the twist was at rest. Now the joints are brought back onto it first."""
    jog, tip = _jog(), TipModel(ARM)
    start = tip.forward(START).copy()
    for k in range(1000):
        if jog.finished:
            break
        if k < 150:
            jog.command(_request("base", [0, 0, 0.25, 0, 0, 0]))    # up
        elif k == 150:
            jog.end("done")
        q, _ = jog.step()
    assert jog.finished
    now = tip.forward(q)
    moved = now[:3, 3] - start[:3, 3]
    assert moved[2] > 0.1
    assert np.linalg.norm(moved[:2]) < 1e-6
    assert np.allclose(now[:3, :3], start[:3, :3], atol=1e-6)


def test_a_silent_guard_holds_a_cartesian_jog_on_its_line():
    """A guard whose figures stop coming (its thread starved: a busy machine) holds the arm;
    a Cartesian jog brakes along its line then, as a stop does, and goes on along it when
    the figures come back. It braked joint by joint and re-anchored its line where it came
    to rest, 0.2 mm off (test_jog's jogs failed so under load)."""
    jog, tip = _jog(guarded=True), TipModel(ARM)
    start = tip.forward(START).copy()
    for k in range(1000):
        if jog.finished:
            break
        if k < 100 or k >= 200:     # the guard's figures: nothing near; silent in between
            jog.keep_clear({"gradient": None, "rate": 0.0})
        if k < 300:
            jog.command(_request("base", [0, 0, 0.25, 0, 0, 0]))
        elif k == 300:
            jog.end("done")
        q, qd = jog.step()
        if k == 199:
            assert np.abs(qd).max() < 1e-9                 # held
    assert jog.finished
    moved = tip.forward(q)[:3, 3] - start[:3, 3]
    assert moved[2] > 0.1
    assert np.linalg.norm(moved[:2]) < 1e-6
    assert np.allclose(tip.forward(q)[:3, :3], start[:3, :3], atol=1e-6)


def test_a_cartesian_jog_the_guard_slows_keeps_its_line():
    """The guard slows a jog near something (its joint velocity scaled down as a whole): a
    Cartesian jog slows along its line. Its line was dropped and taken up again where the
    joints, following a cycle behind, had got to: 0.2 mm off over 14 cm (test_jog)."""
    jog, tip = _jog(guarded=True), TipModel(ARM)
    start = tip.forward(START).copy()
    rise = tip.jacobian(START)[2].copy()       # m/rad: how the tip's height follows each joint
    for k in range(1000):
        if jog.finished:
            break
        if k < 300:   # the clearance above falls as the tip rises: at most 0.1 m/s closer
            jog.keep_clear({"gradient": -rise, "rate": 0.1})
            jog.command(_request("base", [0, 0, 0.25, 0, 0, 0]))
        elif k == 300:
            jog.end("done")
        q, _ = jog.step()
    assert jog.finished
    moved = tip.forward(q)[:3, 3] - start[:3, 3]
    assert 0.05 < moved[2] < 0.25 * 300 * DT * 0.6             # up, slowed
    assert np.linalg.norm(moved[:2]) < 1e-6
    assert np.allclose(tip.forward(q)[:3, :3], start[:3, :3], atol=1e-6)


def test_silence_brakes_to_rest_and_ends_the_session_saying_why():
    jog = _jog(deadman_cycles=50)
    for _ in range(100):
        jog.command(_request("joint", [0, 0, 0, 0, 0, 2.0]))
        jog.step()
    cycles = 0
    while not jog.finished:
        jog.step()
        cycles += 1
    # Braking from 2 rad/s with the deceleration ramped up within the jerk limit (issue 30).
    a, j = ARM.max_acceleration[5], ARM.max_jerk[5]
    braking = (2.0 / a + a / j) / DT
    assert 50 < cycles <= 50 + math.ceil(braking) + 3
    assert jog.ending[0] == "aborted" and "deadman" in jog.ending[1]


def test_a_released_deadman_holds_and_a_joint_stops_inside_its_range():
    jog = _jog(deadman_cycles=10 ** 6)
    for _ in range(50):
        jog.command(_request("joint", [0, 0, 0, 0, 0, 2.0], deadman=False))
        q, qd = jog.step()
    assert not np.any(qd) and np.allclose(q, START)
    for _ in range(1000):
        jog.command(_request("joint", [0, 0, 0, 0, 10.0, 0]))   # joint 5 as fast as it goes
        q, qd = jog.step()
    assert ARM.upper[4] - 2e-3 < q[4] <= ARM.upper[4] and qd[4] == 0.0


def test_a_late_clearance_allows_no_approach_and_a_silent_guard_holds_the_arm():
    """The guard's figures hold for a few cycles only (jog_guard.py sends them every other
    cycle): a stalled guard must not let the arm use up the room it reported long ago."""
    jog = _jog(deadman_cycles=10 ** 6)
    jog.keep_clear({"gradient": [0, 0, 0, 0, 0, -0.1], "rate": 0.1})   # J6+ closes 0.1 m/rad
    for _ in range(STALE_CYCLES):
        jog.command(_request("joint", [0, 0, 0, 0, 0, 2.0]))
        _, qd = jog.step()
    assert qd[5] > 0.0                                    # approaching at the rate allowed
    for _ in range(200):                                  # the guard falls silent
        jog.command(_request("joint", [0, 0, 0, 0, 0, 2.0]))
        _, qd = jog.step()
    assert qd[5] == 0.0                                   # no approach on old figures
    for _ in range(100):
        jog.command(_request("joint", [0, 0, 0, 0, 0, -2.0]))
        _, qd = jog.step()
    assert qd[5] < -1.0                                   # moving away stays free

    jog = _jog(deadman_cycles=10 ** 6, guarded=True)      # a guard that never speaks
    for _ in range(STALE_CYCLES + 200):
        jog.command(_request("joint", [0, 0, 0, 0, 0, 2.0]))
        _, qd = jog.step()
    assert not np.any(qd)                                 # no word from the guard: held


@pytest.mark.parametrize("velocity, released", [
    ([0.661, -0.007, 0.521, 0, 0, 0], ()),                         # it starts
    ([0.63, 0.581, 1.295, 0.845, -0.144, 0.787], range(113, 172)),  # and starts again
])
def test_a_cartesian_jog_whose_joints_lag_its_line_keeps_the_manual_speed(velocity, released):
    """The joints follow the line's twist a few cycles behind where their accelerations cannot
    keep up; the line's correction then asks up to the manual speed, and the jerk-limited
    tracker, speeding up towards it, cannot stop speeding up in time: the tip was commanded at
    286 mm/s (test_jog saw 254.5 mm/s on the real server, under load). Commanded speeds are
    measured as the issue measured them: the chord of the tip's setpoints over a cycle."""
    jog, tip = _jog(), TipModel(ARM)
    previous = tip.forward(START)[:3, 3].copy()
    speeds = []
    for k in range(300):
        jog.command(_request("base", velocity, deadman=k not in released))
        q, _ = jog.step()
        now = tip.forward(q)[:3, 3].copy()
        speeds.append(np.linalg.norm(now - previous) / DT)
        previous = now
    assert max(speeds) <= MANUAL_TIP_SPEED * (1 + 1e-6)
    # Jogging at speed (the headroom's), not held back: for 80 ms at least.
    assert np.count_nonzero(np.array(speeds) > 0.94 * MANUAL_TIP_SPEED) >= 20
