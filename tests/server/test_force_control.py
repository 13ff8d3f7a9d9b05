"""The sensor loops of force_control.py on their own: the guard's crossing rule and envelope,
the admittance law against a simulated spring and the force settling after a guarded stop,
without a controller."""
from __future__ import annotations

import math

import numpy as np
import pytest

from landscape.server.cycle.force_loops import (SETTLE_BAND, SETTLE_REACH, SETTLE_TIME, Admittance,
                                            ComplySpec, ForceSettle, GuardSpec, ThresholdMonitor)
from landscape.server.cycle.tip_model import TipModel
from landscape.robot.arm import arm_model

CUP = np.eye(4)
CUP[2, 3] = 0.12


def _force(fz: float) -> np.ndarray:
    sensors = np.full(7, math.nan)
    sensors[:6] = [0, 0, fz, 0, 0, 0]
    return sensors


def _range(distance: float) -> np.ndarray:
    sensors = np.full(7, math.nan)
    sensors[6] = distance
    return sensors


@pytest.mark.parametrize("threshold, readings, fires_at", [
    (-20.0, [0, -5, -19.9, -20.0], 3),      # falling to a negative threshold
    (20.0, [0, -30, 19, 21], 3),            # rising to a positive one; the other side never
    (-20.0, [0, 5, 30, 60], None),          # the other way: no crossing
])
def test_a_guard_fires_when_its_component_reaches_the_threshold_from_its_side(
        threshold, readings, fires_at):
    guard = ThresholdMonitor(GuardSpec("force_torque", (0, 0, threshold), (0, 0, 0), 1.0, CUP))
    verdicts = [guard.check(_force(f)) for f in readings]
    fired = [i for i, v in enumerate(verdicts) if v is not None]
    assert (fired[0] if fired else None) == fires_at
    if fires_at is not None:
        assert verdicts[fires_at][0] == "triggered"


def test_a_range_guard_treats_nothing_in_range_as_far_and_the_envelope_ends_it():
    guard = ThresholdMonitor(GuardSpec("laser_range", (0.05, 0, 0), (0, 0, 0), 1.0, CUP))
    assert guard.check(_range(math.nan)) is None and guard.check(_range(0.2)) is None
    assert guard.check(_range(0.049))[0] == "triggered"
    guard = ThresholdMonitor(GuardSpec("force_torque", (0, 0, -50), (0, 0, 10), 1.0, CUP))
    assert guard.check(_force(-9)) is None
    assert guard.check(_force(-11))[0] == "envelope"


def test_a_filtered_guard_needs_the_reading_to_stay():
    guard = ThresholdMonitor(GuardSpec("force_torque", (0, 0, -20), (0, 0, 0), 0.25, CUP))
    assert guard.check(_force(0)) is None
    assert guard.check(_force(-40)) is None          # one spike: the filter holds it at -10
    assert guard.check(_force(0)) is None
    verdicts = [guard.check(_force(-40)) for _ in range(10)]
    assert any(v is not None for v in verdicts)


def test_the_admittance_loop_settles_a_spring_at_the_set_point_within_its_limits():
    """The tool presses into a spring of 20 N/mm along its z: the loop's offset settles where
    the spring pushes back with the set-point, and the joints follow along the tool's z."""
    tip, dt = TipModel(arm_model()), 0.004
    spec = ComplySpec(axes=(False, False, True), setpoint=(0, 0, -20), kp=(0, 0, 0.001),
                      kd=(0, 0, 0), reach=(0, 0, 0.01), envelope=(0, 0, 0), travel=(0, 0, 0),
                      speed=0.02, acceleration=5.0, timeout=0, hold_only=True, panic=0,
                      tool_offset=CUP)
    loop = Admittance(spec, tip, dt)
    q = np.array([0.0, 0.3, 1.4, 0.0, 1.44, 0.0])
    tip.set_tool(CUP)
    start = tip.forward(q).copy()
    offsets = []
    for _ in range(500):
        depth = loop.offset[2]                      # the spring's surface is where it began
        commanded = loop.shift(q, _force(-20000.0 * max(depth, 0.0)), True)
        offsets.append(loop.offset[2])
    assert loop.problem is None
    assert offsets[-1] == pytest.approx(0.001, rel=0.01)     # 20 N at 20 N/mm
    assert np.max(np.diff(offsets)) <= spec.speed * dt * (1 + 1e-9)
    moved = tip.forward(commanded)
    tool_z = start[:3, 2]
    assert (moved[:3, 3] - start[:3, 3]) == pytest.approx(0.001 * tool_z, abs=1e-6)
    assert np.allclose(moved[:3, :3], start[:3, :3], atol=1e-6)


def test_the_admittance_loop_panics_past_its_compliance_distance():
    tip = TipModel(arm_model())
    spec = ComplySpec(axes=(False, False, True), setpoint=(0, 0, -20), kp=(0, 0, 0.001),
                      kd=(0, 0, 0), reach=(0, 0, 0.002), envelope=(0, 0, 0), travel=(0, 0, 0),
                      speed=0.02, acceleration=5.0, timeout=0, hold_only=True, panic=1,
                      tool_offset=CUP)
    loop = Admittance(spec, tip, 0.004)
    q = np.array([0.0, 0.3, 1.4, 0.0, 1.44, 0.0])
    for _ in range(200):                             # nothing to press on: it goes on and on
        loop.shift(q, _force(0.0), True)
    assert loop.problem.startswith("panic") and abs(loop.offset[2]) == pytest.approx(0.002)
    assert loop.summary(_force(0.0))["panic"] == 1


def _settle(speed: float, spring: float | None, cycles: int = 1000):
    """A guarded stop on fz = -20 N after approaching along the tool's z at `speed` (m/s),
    settled against a spring of `spring` N/m already pressed 0.5 mm (None: nothing there)."""
    spec = GuardSpec("force_torque", (0, 0, -20), (0, 0, 0), 1.0, CUP, (0, 0, 0.1), speed, 5.0)
    assert ForceSettle.wanted(spec)
    settle = ForceSettle(spec, TipModel(arm_model()), 0.004)
    q = np.array([0.0, 0.3, 1.4, 0.0, 1.44, 0.0])
    for k in range(cycles):
        depth = 0.0005 + settle.loop.offset[2]
        settle.shift(q, _force(0.0 if spring is None else -spring * max(depth, 0.0)))
        if settle.finished:
            return settle, k
    return settle, cycles


def test_force_settling_after_a_guarded_stop_ends_near_the_threshold_or_at_its_bounds():
    settle, cycles = _settle(0.04, 20000.0)     # 10 N at the stop: pressed on to 20 N
    assert settle.finished and settle.note == ""
    assert settle.loop.force[2] == pytest.approx(-20, rel=SETTLE_BAND)
    assert cycles * 0.004 < SETTLE_TIME
    settle, _ = _settle(0.04, None)             # nothing there: it gives up after 5 mm
    assert settle.finished and settle.note == "the force did not settle within 5 mm"
    assert abs(settle.loop.offset[2]) == pytest.approx(SETTLE_REACH)
    settle, cycles = _settle(0.001, 100.0)      # too slow for a soft spring: 2 s at most
    assert settle.note == "the force did not settle within 2 s"
    assert cycles == pytest.approx(SETTLE_TIME / 0.004, abs=1)
    settle, _ = _settle(0.04, 20000.0, cycles=5)
    settle.stop("stop while settling the force")
    offset = settle.loop.offset.copy()
    settle.shift(np.array([0.0, 0.3, 1.4, 0.0, 1.44, 0.0]), _force(0.0))
    assert settle.finished and np.all(settle.loop.offset == offset)   # it holds there


def test_only_a_force_guard_on_the_approach_axis_settles():
    def spec(kind, thresholds, approach, speed=0.04):
        return GuardSpec(kind, thresholds, (0, 0, 0), 1.0, CUP, approach, speed, 5.0)
    assert not ForceSettle.wanted(spec("laser_range", (0.05, 0, 0), (0, 0, 0.1)))
    assert not ForceSettle.wanted(spec("force_torque", (-5, 0, 0), (0, 0, 0.1)))  # side hit
    assert not ForceSettle.wanted(spec("force_torque", (0, 0, -20), (0, 0, 0.1), speed=0))
