"""The sensor loops of guarded and compliant motion (seed 3.7.2), run every cycle in the cycle.

The Executor (executor.py) plays a motion's planned trajectory as usual; these ride on it:

- `ThresholdMonitor` (moveReact): watches up to three sensor components and says when one
  crosses its threshold (the move then stops at the arm's full deceleration and is done) or
  leaves its envelope (the move stops and fails).
- `ForceSettle` (moveReact on a force): once stopped, settles the force near its threshold.
  At the moment a force threshold is crossed, part of the reading is the contact's damping
  (it grows with the approach speed), and the braking adds depth: at rest the force would be
  off the threshold by what the speed made of it (36 % at 40 mm/s on the cup). So after the
  braking, an admittance along the watched axes the move approached on moves the tool until
  the force is within SETTLE_BAND of the threshold for SETTLE_CYCLES cycles, at most
  SETTLE_REACH from where it stopped, for at most SETTLE_TIME, no faster than the approach.
- `Admittance` (comply): shifts the planned setpoint along the force-controlled tool axes so
  that the sensed force there approaches its set-point: the offset moves at
  kp * (F - F*) + kd * d(F - F*)/dt (admittance control), limited in speed, acceleration and
  reach; the joints follow through the tip Jacobian (pinocchio, tip_model.py). Positions stay
  controlled along the other axes (hybrid force/position control).

Sensor components: a force/torque sensor gives (fx, fy, fz) at the tool tip in the tool frame
(N; pressing the tip into a surface along +z of the tool reads fz < 0); a range sensor gives
its distance (m) as the first component (nothing in range counts as infinitely far).

The specs are plain frozen records (they cross the process boundary); arrays are SI.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

from landscape.server.cycle.feedback import FORCE_TORQUE, RANGE
from landscape.server.cycle.tip_model import TipModel, damped_solve, wrench_map

FORCE, RANGE_KIND = "force_torque", "laser_range"
PANIC_HOLD, PANIC_DRIVES_OFF = 0, 1

# Force settling after a guarded stop (ForceSettle). The gain keeps the loop well damped on
# contacts up to some 50 kN/m (gain * stiffness * cycle well below the loop's few cycles of
# lag); the cell's tools touch at 5 to 20 kN/m.
SETTLE_GAIN = 0.0005       # (m/s)/N
SETTLE_BAND = 0.05         # of |threshold|
SETTLE_CYCLES = 10         # in the band this long: settled
SETTLE_REACH = 0.005       # m, per axis, from where the braking ended
SETTLE_TIME = 2.0          # s


def components(kind: str, sensors: np.ndarray, at_tip: np.ndarray) -> np.ndarray:
    """(3,) the components a guard or a compliance loop looks at, from the ring's sensor
    values (7,); at_tip: the (6, 6) map of the flange's wrench to the tip (wrench_map)."""
    if kind == FORCE:
        return (at_tip @ sensors[FORCE_TORQUE])[:3]
    distance = sensors[RANGE]
    return np.array([math.inf if math.isnan(distance) else distance, math.nan, math.nan])


@dataclass(frozen=True)
class GuardSpec:
    """moveReact's monitor. thresholds (3,): signed, 0 = component not watched; the move stops
    when a watched component reaches its threshold from the side it started on. envelope (3,):
    |component| above it ends the move as failed (0: none). gain: weight of the newest reading
    in an exponential filter (1: none). tool_offset (4, 4): the tip in the flange. approach
    (3,): the move in the tool frame (m); speed (m/s) and acceleration (m/s^2): its linear
    limits, the force settling's (none without a speed)."""

    kind: str
    thresholds: tuple[float, float, float]
    envelope: tuple[float, float, float]
    gain: float
    tool_offset: np.ndarray = field(default_factory=lambda: np.eye(4))
    approach: tuple[float, float, float] = (0.0, 0.0, 0.0)
    speed: float = 0.0
    acceleration: float = 0.0


class ThresholdMonitor:
    def __init__(self, spec: GuardSpec):
        self.spec = spec
        self.thresholds = np.array(spec.thresholds, dtype=float)
        self.watched = self.thresholds != 0
        self.envelope = np.array(spec.envelope, dtype=float)
        self.filtered: np.ndarray | None = None
        self.side: np.ndarray | None = None     # sign of (value - threshold) at the start
        self._at_tip = wrench_map(spec.tool_offset)

    def reading(self, sensors: np.ndarray) -> np.ndarray:
        """(3,) the watched sensor's components now, unfiltered."""
        return components(self.spec.kind, sensors, self._at_tip)

    def check(self, sensors: np.ndarray) -> tuple[str, np.ndarray] | None:
        """None while nothing happened; ("triggered", values) or ("envelope", values)."""
        value = self.reading(sensors)
        if self.filtered is not None:   # (a range to or from nothing in sight: unfiltered)
            known = np.isfinite(self.filtered) & np.isfinite(value)
            value = value.copy()
            value[known] += (1.0 - self.spec.gain) * (self.filtered[known] - value[known])
        self.filtered = value
        bounded = self.envelope > 0
        if np.any(np.abs(value[bounded]) > self.envelope[bounded]):
            return "envelope", value
        side = np.sign(value - self.thresholds)
        if self.side is None:
            self.side = side
        if np.any(self.watched & ((side == 0) | (side != self.side))):
            return "triggered", value
        return None


@dataclass(frozen=True)
class ComplySpec:
    """comply's loop. Per tool axis x, y, z: `axes` force-controlled or not, `setpoint` (N),
    `kp` ((m/s)/N), `kd` (m/N), `reach` (m, the furthest the offset may go), `envelope` (N,
    |force| above it panics; 0: none), `travel` (m, the tip's furthest from where it started;
    0: none). speed (m/s) and acceleration (m/s^2) bound the offset's motion. timeout: cycles
    of compliance (0: none); hold_only: no planned motion, the compliance lasts `timeout`
    cycles and is done. panic: PANIC_HOLD (stop and hold) or PANIC_DRIVES_OFF (stop, then the
    server powers down into Error)."""

    axes: tuple[bool, bool, bool]
    setpoint: tuple[float, float, float]
    kp: tuple[float, float, float]
    kd: tuple[float, float, float]
    reach: tuple[float, float, float]
    envelope: tuple[float, float, float]
    travel: tuple[float, float, float]
    speed: float
    acceleration: float
    timeout: int
    hold_only: bool
    panic: int
    tool_offset: np.ndarray = field(default_factory=lambda: np.eye(4))


class Admittance:
    """The compliance loop of one motion: `shift` turns each planned setpoint into the
    commanded one; `problem` says why it must stop (a panic, or the timeout) once it must."""

    # Weights of the newest sample in the filters of the force (about 3 cycles: the contact's
    # damping makes the raw force jump with every cycle's step) and of its derivative.
    FORCE_FILTER = 0.3
    DERIVATIVE_FILTER = 0.2

    def __init__(self, spec: ComplySpec, tip: TipModel, dt: float):
        self.spec, self.tip, self.dt = spec, tip, dt
        self.axes = np.array(spec.axes, dtype=bool)
        self.setpoint = np.array(spec.setpoint, dtype=float)
        self.kp, self.kd = np.array(spec.kp, dtype=float), np.array(spec.kd, dtype=float)
        self.reach = np.array(spec.reach, dtype=float)
        self.envelope = np.array(spec.envelope, dtype=float)
        self.travel = np.array(spec.travel, dtype=float)
        self.offset = np.zeros(3)          # m, tool axes at the start
        self.rate = np.zeros(3)            # m/s
        self.dq = np.zeros(6)              # rad, added to the planned setpoint
        self.cycles = 0
        self.problem: str | None = None  # why it must stop: a panic (`panic`) or the timeout
        self.panic = True
        self._force: np.ndarray | None = None
        self._error: np.ndarray | None = None
        self._derivative = np.zeros(3)
        self._start: np.ndarray | None = None   # the tip (4, 4) where the compliance began
        self._at_tip = wrench_map(spec.tool_offset)

    @property
    def force(self) -> np.ndarray | None:
        """(3,) the filtered force the loop acts on, N; None before its first update."""
        return self._force

    @property
    def holding(self) -> bool:
        """A hold-only compliance whose time is not up: its motion stays at its end point."""
        return (self.spec.hold_only and self.problem is None
                and self.cycles < self.spec.timeout)

    def shift(self, nominal: np.ndarray, sensors: np.ndarray, active: bool) -> np.ndarray:
        """The commanded joints (6,) for the planned ones; the loop runs while `active` (the
        motion runs; stopping or paused, the offset holds)."""
        tip = self.tip
        tip.set_tool(self.spec.tool_offset)
        planned = tip.forward(nominal).copy()
        if self._start is None:
            self._start = planned
        if active and self.problem is None:
            self._update(sensors, planned)
        target = planned.copy()
        target[:3, 3] += self._start[:3, :3] @ self.offset
        q = nominal + self.dq
        jacobian = tip.jacobian(q)
        self.dq += damped_solve(jacobian, tip.pose_error(target))
        return nominal + self.dq

    def summary(self, sensors: np.ndarray) -> dict:
        """What the motion's final report says about its compliance."""
        return {"offset": self.offset.tolist(),
                "force": components(FORCE, sensors, self._at_tip).tolist(),
                "panic": self.spec.panic if self.problem is not None and self.panic else None}

    def _update(self, sensors: np.ndarray, planned: np.ndarray) -> None:
        spec, dt = self.spec, self.dt
        self.cycles += 1
        raw = components(FORCE, sensors, self._at_tip)
        bounded = self.envelope > 0
        if np.any(np.abs(raw[bounded]) > self.envelope[bounded]):
            self.problem = (f"panic: force {vector(raw)} N beyond the envelope "
                            f"{vector(self.envelope)} N")
            return
        if self._force is None:
            self._force = raw.copy()
        self._force += self.FORCE_FILTER * (raw - self._force)
        force = self._force
        error = np.where(self.axes, force - self.setpoint, 0.0)
        if self._error is not None:
            self._derivative += self.DERIVATIVE_FILTER * ((error - self._error) / dt
                                                          - self._derivative)
        self._error = error
        wanted = np.clip(self.kp * error + self.kd * self._derivative, -spec.speed, spec.speed)
        step = spec.acceleration * dt
        self.rate += np.clip(wanted - self.rate, -step, step)
        self.offset += self.rate * dt
        if np.any(np.abs(self.offset) > self.reach):
            self.offset = np.clip(self.offset, -self.reach, self.reach)
            self.problem = (f"panic: the force set-point {vector(self.setpoint)} N was not "
                            f"held within the compliance distance {vector(self.reach)} m "
                            f"(contact lost, or pushed back)")
            return
        moved = self._start[:3, :3].T @ (planned[:3, 3] - self._start[:3, 3]) + self.offset
        limited = self.travel > 0
        if np.any(np.abs(moved[limited]) > self.travel[limited]):
            self.problem = (f"panic: the tip moved {vector(moved)} m from where the comply "
                            f"began, beyond the travel limits {vector(self.travel)} m")
            return
        if spec.timeout and self.cycles >= spec.timeout and not spec.hold_only:
            self.problem = (f"timeout: the motion was not done within "
                            f"{spec.timeout * dt:g} s")
            self.panic = False


class ForceSettle:
    """The force settling of a guarded move stopped on a force threshold (module docstring):
    `shift` turns the stopped setpoint into the commanded one every cycle; `finished` once
    settled, out of bounds or stopped, `note` then says why if it did not settle."""

    def __init__(self, spec: GuardSpec, tip: TipModel, dt: float):
        thresholds = np.array(spec.thresholds, dtype=float)
        self.axes = (thresholds != 0) & (np.array(spec.approach) != 0)
        self.setpoint = np.where(self.axes, thresholds, 0.0)
        self.band = SETTLE_BAND * np.abs(self.setpoint)
        self.timeout = math.ceil(SETTLE_TIME / dt)
        self.loop = Admittance(ComplySpec(
            axes=tuple(self.axes), setpoint=tuple(self.setpoint),
            kp=tuple(np.where(self.axes, SETTLE_GAIN, 0.0)), kd=(0.0,) * 3,
            reach=tuple(np.where(self.axes, SETTLE_REACH, 0.0)), envelope=spec.envelope,
            travel=(0.0,) * 3, speed=spec.speed, acceleration=spec.acceleration,
            timeout=self.timeout, hold_only=True, panic=PANIC_HOLD,
            tool_offset=spec.tool_offset), tip, dt)
        self.finished = False
        self.note = ""
        self._calm = 0     # cycles in a row within the band

    @classmethod
    def wanted(cls, spec: GuardSpec) -> bool:
        """Whether a stop on `spec`'s threshold settles: a force guard with a speed, watching
        an axis the move approached on."""
        return (spec.kind == FORCE and spec.speed > 0
                and bool(np.any(np.array(spec.thresholds) * np.array(spec.approach) != 0)))

    def shift(self, nominal: np.ndarray, sensors: np.ndarray) -> np.ndarray:
        q = self.loop.shift(nominal, sensors, not self.finished)
        if self.finished:
            return q
        loop = self.loop
        if loop.problem is not None:
            self.stop("the force did not settle within "
                      f"{SETTLE_REACH * 1000:g} mm" if "distance" in loop.problem
                      else loop.problem)
            return q
        within = np.all(np.abs(loop.force - self.setpoint)[self.axes] <= self.band[self.axes])
        self._calm = self._calm + 1 if within else 0
        if self._calm >= SETTLE_CYCLES:
            self.finished = True
        elif loop.cycles >= self.timeout:
            self.stop(f"the force did not settle within {SETTLE_TIME:g} s")
        return q

    def stop(self, note: str) -> None:
        """End the settling where it is now (the offset holds)."""
        self.finished, self.note = True, note


def vector(v) -> str:
    """Values for a message: "(1.5, -2, 0.25)"."""
    return "(" + ", ".join(f"{x:.4g}" for x in v) + ")"
