"""Guarded and compliant motion (seed 3.7.2 moveReact and comply): checks, planning, and what
their events say. The loops themselves run in the cycle (force_loops.py).

What the seed leaves open, decided as a cell integrator would expect:
- Both move relative to the tool tip, in the tool frame (`motion` x, y, z), in a straight
  line at `speed` % of the maximum speed. moveReact tares the force sensor when it starts (in
  the air, as a search begins), so that its thresholds count contact forces, not the tool's
  weight; comply does not (it usually starts in contact): its set-points count from the last
  tare (moveReact's, or SendCommand "tare <sensor>").
- moveReact watches the sensor's components (force sensor: fx, fy, fz at the tip in the tool
  frame, N; range sensor: the distance, first component only). Thresholds are signed: a move
  stops when a watched (non-zero) component reaches its threshold from the side it started
  on (pressing down on a table with the tool pointing down: fz falls, a threshold of -20 N).
  It stops at the arm's full deceleration; on a force threshold it then settles the force
  near the threshold (force_loops.ForceSettle: along the watched axes it approached on,
  within 5 % of the threshold, at most 5 mm and 2 s, no faster than the approach), so that at
  rest the force is the threshold's whatever the approach speed. Then it is done; the done
  event says whether it triggered, the reading and the tip's position (world frame) at the
  trigger, and the reading at rest. With no crossing it runs its full distance and says so.
  `gains[0]` in [0, 1] filters the readings (the newest one's weight; 0 and 1: none); the
  others are ignored, as in the seed. `envelope_max[i] > 0`: a
  component beyond it ends the move as failed (an alarm); `envelope_min` is ignored, as in the
  seed. The compliance vector and speed must be zero ("mov-til-touch"; Comply complies).
- Both are meant to touch something: the collision check before they start allows the tool,
  or the part it holds, to meet the bodies it would meet on the way (the surface searched for,
  the table slid along), and only those two; the arm's links stay checked against everything,
  those bodies included. Comply from rest is also checked with its compliance: the tool
  offset by the compliance distances (each corner of the box they span, along the tool's
  axes) at the start and at the end of its motion, reached by a straight line from there.
  Not checked: the offset's path between those corners (it follows the force, unknown before),
  corners the arm cannot reach (the travel limits and the envelope bound the offset there),
  and Comply joining a running motion (that motion was checked when it started, with no
  contact allowed; the compliance it adds is bounded by its distances and envelope only).
- comply controls the force along the tool axes where `compliance` is non-zero (hybrid force /
  position control; |compliance| is the furthest the tool may give along that axis) and
  follows `motion` along the others (it must be zero on the compliant axes). Set-points are
  `thresholds[0:3]` (N, signed as the sensor reads; torques are not controlled and must be 0).
  The offset moves at kp * (F - F*) + kd * d(F - F*)/dt, within `compliance_speed` % of the
  maximum linear speed; gains are per axis, in (length unit / s) / N and length unit / N.
  `max_travel_distances` (x, y, z; 0: none) bound the tip's travel from where it began.
  `max_timeout` (s): with a motion, the longest it may take (then it fails); with no motion,
  how long the force is held (then it is done). Exceeding the envelope (`envelope_max`, N per
  axis, 0: none), the travel or the compliance distance is a panic; `panic_stop_code` says what
  follows: 0 stop and hold (the command fails, an alarm), 1 stop, then drives off and Error
  (Reset to go on). From Moving, comply adds its compliance to the running motion (its motion
  must be zero; the running command's id is returned and its done event ends the compliance).
"""
from __future__ import annotations

import itertools
import math
from typing import Callable

import numpy as np

from landscape.robot.arm import ArmModel
from landscape.robot.kinematics import Kinematics
from landscape.server.cycle.force_loops import (FORCE, PANIC_DRIVES_OFF, PANIC_HOLD, ComplySpec,
                                                GuardSpec, vector)
from landscape.server.device.motion_control import MotionControl
from landscape.server.device.state_machine import StateMachine
from landscape.server.device.states import State
from landscape.server.device.stored_settings import SettingsKeeper
from landscape.server.errors import OutOfRange, ParamError, Unreachable, WrongState
from landscape.server.events import alarms
from landscape.server.planning.collision import AllowedContact, CollisionScene, check_motion
from landscape.server.planning.collision.shapes import ARM_LINKS
from landscape.server.planning.motion.trajectory import Trajectory
from landscape.server.planning.targets import Frame
from landscape.server.workcell.sensing import Sensors

MAX_COMPLY_TIMEOUT = 600.0    # s
OFFSET_SPEED = 10.0           # %: the offset moves checked (the speed changes nothing there)
MAX_CONTACTS = 6              # (tool or held part, body) a guarded or compliant motion may make
PANIC_CODES = {PANIC_HOLD: "stop and hold", PANIC_DRIVES_OFF: "stop, then drives off"}


class GuardedMotion:
    """fault(code, message): into Error with the drives off (a compliance panic asks for it)."""

    def __init__(self, motions: MotionControl, state: StateMachine, sensors: Sensors,
                 kinematics: Kinematics, collisions: CollisionScene, settings: SettingsKeeper,
                 arm: ArmModel, cycle_time: float, fault: Callable[[int, str], None]):
        self.motions, self.state, self.sensors = motions, state, sensors
        self.kinematics, self.collisions, self.settings = kinematics, collisions, settings
        self.arm, self.cycle_time, self.fault = arm, cycle_time, fault

    # ---- seed 3.7.2 moveReact ---------------------------------------------------------------

    def move_react(self, sensor: str, motion: np.ndarray, compliance: np.ndarray, speed: float,
                   compliance_speed: float, thresholds: np.ndarray, gains: np.ndarray,
                   envelope_max: np.ndarray) -> str:
        """Values in SI (lengths m; force N). Returns the command id."""
        kind = self._ring_sensor(sensor)
        _finite("motion", motion, compliance, thresholds, gains, envelope_max)
        if np.any(compliance) or compliance_speed:
            raise ParamError("MoveReact moves until a sensor reacts; its compliance and "
                             "compliance speed must be zero (Comply complies)")
        if not np.any(motion):
            raise ParamError("MoveReact needs a motion (x, y, z in the tool frame)")
        if not np.any(thresholds):
            raise ParamError("MoveReact needs a non-zero threshold")
        if kind != FORCE and np.any(thresholds[1:]):
            raise ParamError(f"{sensor} has one component: only the first threshold applies")
        if not 0.0 <= gains[0] <= 1.0:
            raise OutOfRange(f"the first gain weighs the newest reading, 0 to 1; got {gains[0]}")
        if np.any(envelope_max < 0):
            raise OutOfRange(f"envelope maxima are magnitudes, 0 or more; got {envelope_max}")
        trajectory = self._tool_move(motion, speed)
        settings = self.settings.current
        limits = self.motions.planner.limits(settings, speed)
        guard = GuardSpec(kind, tuple(thresholds), tuple(envelope_max),
                          float(gains[0]) or 1.0, settings.tool_offset, tuple(motion),
                          limits.linear_velocity, limits.linear_acceleration)
        # Checked before the tare: a refused MoveReact leaves the sensor as it was (a tare
        # cannot be undone).
        self.motions.check_collisions([trajectory], f"MoveReact {sensor}",
                                      allow=self._meant_to_touch([trajectory]))
        if kind == FORCE:
            self.sensors.tare(sensor)
        return self.motions.start(
            "MoveReact", sensor, [trajectory], loops={"guard": guard}, checked=True,
            finish=lambda report: self._react_outcome(report, kind))

    def _react_outcome(self, report: dict, kind: str) -> str:
        guard = report.get("guard", {})
        event = guard.get("event")
        if event == "triggered":
            values = guard["values"][:3 if kind == FORCE else 1]
            unit = "N" if kind == FORCE else "m"
            rest = (f"; at rest {vector(guard['rest'][:len(values)])} {unit}"
                    if "rest" in guard else "")
            if "peak" in guard:   # how far past the threshold it went while braking
                rest += f"; peak {vector(guard['peak'][:len(values)])} {unit}"
            settle = f" ({guard['settle']})" if "settle" in guard else ""
            return (f"triggered: reading {vector(values)} {unit} with the tip at "
                    f"{vector(self._tip_in_world(guard['position']))} m (world frame)"
                    f"{rest}{settle}")
        if event == "full distance" and report["op"] == "done":
            return "not triggered: moved the full distance"
        return report.get("message", "")

    def _tip_in_world(self, joints) -> np.ndarray:
        settings = self.settings.current
        tip = self.kinematics.forward(np.asarray(joints)) @ settings.tool_offset
        return (settings.base_in_world @ tip)[:3, 3]

    # ---- seed 3.7.2 comply ------------------------------------------------------------------

    def comply(self, sensor: str, thresholds: np.ndarray, max_timeout: float, panic_code: int,
               travel: np.ndarray, kp: np.ndarray, kd: np.ndarray, motion: np.ndarray,
               compliance: np.ndarray, speed: float, compliance_speed: float,
               envelope_max: np.ndarray) -> str:
        """Values in SI (lengths m, forces N, gains (m/s)/N and m/N, times s); the arrays of
        6 (thresholds, travel, gains) may come empty (all zero). Returns the command id."""
        if self._ring_sensor(sensor) != FORCE:
            raise ParamError(f"Comply holds a force: {sensor} is not a force sensor")
        thresholds, travel, kp, kd = (_six(name, v) for name, v in (
            ("thresholds", thresholds), ("max_travel_distances", travel),
            ("proportional_gains", kp), ("differential_gains", kd)))
        _finite("comply", thresholds, travel, kp, kd, motion, compliance, envelope_max,
                np.array([max_timeout, speed, compliance_speed]))
        axes = compliance != 0
        if not np.any(axes):
            raise ParamError("Comply needs a compliance direction: a non-zero compliance "
                             "distance along x, y or z of the tool")
        if np.any(thresholds[3:]):
            raise OutOfRange("torque set-points are not supported: thresholds 4 to 6 must be 0")
        if np.any(thresholds[:3][~axes]):
            raise ParamError("a force set-point needs compliance along its axis")
        if np.any(motion[axes]):
            raise ParamError("the motion must be orthogonal to the compliance: zero along the "
                             "compliant axes")
        if np.any(kp[:3][axes] <= 0) or np.any(kd < 0):
            raise OutOfRange("each compliant axis needs a proportional gain above 0 (e.g. "
                             "0.001 (m/s)/N), and differential gains are 0 or more")
        if np.any(travel < 0) or np.any(envelope_max < 0):
            raise OutOfRange("travel distances and envelope maxima are 0 or more")
        if not 0.0 <= max_timeout <= MAX_COMPLY_TIMEOUT:
            raise OutOfRange(f"max_timeout must be 0 to {MAX_COMPLY_TIMEOUT:g} s")
        if not 0.0 < compliance_speed <= 100.0:
            raise OutOfRange("compliance_speed must be above 0 and at most 100 %")
        if panic_code not in PANIC_CODES:
            raise OutOfRange("panic_stop_code is one of " + ", ".join(
                f"{code} ({what})" for code, what in PANIC_CODES.items()))
        arm, dt = self.arm, self.cycle_time
        moving = self.state.state is State.MOVING
        hold_only = not np.any(motion)
        if moving and not hold_only:
            raise ParamError("while moving, Comply adds its compliance to the running motion: "
                             "its own motion must be zero")
        if hold_only and not moving and max_timeout == 0:
            raise ParamError("Comply without a motion holds the force for max_timeout "
                             "seconds: give one")
        spec = ComplySpec(
            axes=tuple(bool(a) for a in axes), setpoint=tuple(thresholds[:3]),
            kp=tuple(kp[:3]), kd=tuple(kd[:3]), reach=tuple(np.abs(compliance)),
            envelope=tuple(envelope_max), travel=tuple(travel[:3]),
            speed=arm.max_linear_velocity * compliance_speed / 100.0,
            acceleration=arm.max_linear_acceleration * self.settings.current.accel_percent / 100,
            timeout=math.ceil(max_timeout / dt), hold_only=hold_only and not moving,
            panic=panic_code, tool_offset=self.settings.current.tool_offset)
        finish = self._comply_outcome
        if moving:
            return self._join_running(spec, finish)
        start = self.motions.planning_start()
        trajectory = (Trajectory(dt, start[None, :].copy(), np.zeros((1, 6))) if hold_only
                      else self._tool_move(motion, speed))
        offsets = self._offset_moves(trajectory, spec)
        allow = self._meant_to_touch([trajectory, *offsets])
        for offset in offsets:
            self.motions.check_collisions([offset], "Comply with its compliance offset",
                                                 allow=allow)
        return self.motions.start("Comply", sensor, [trajectory], allow=allow,
                                         loops={"comply": spec}, finish=finish)

    def _offset_moves(self, trajectory, spec: ComplySpec) -> list:
        """Straight tool moves from the motion's start and end to each corner of the box the
        compliance may offset the tool within; corners out of the arm's reach are left out."""
        axes = np.flatnonzero(spec.axes)
        ends = trajectory.positions[[0, -1] if len(trajectory) > 1 else [0]]
        moves = []
        for signs in itertools.product((-1.0, 1.0), repeat=len(axes)):
            corner = np.zeros(3)
            corner[axes] = np.array(signs) * np.array(spec.reach)[axes]
            for q in ends:
                try:
                    moves.append(self._tool_move(corner, OFFSET_SPEED, q))
                except Unreachable:
                    continue      # unreachable: see the module docstring
        return moves

    def _join_running(self, spec: ComplySpec, finish) -> str:
        """Comply from Moving: compliance for the running motion."""
        motions = self.motions
        with self.state.atomic() as state:
            running = motions.running
            if running is None or state.state is not State.MOVING:
                raise WrongState("no motion is running", state=state.state.value)
            if running.command in ("Jog", "Comply"):
                raise WrongState(f"Comply cannot join a {running.command}")
            if running.finish is None:
                running.finish = finish
            else:
                first = running.finish
                running.finish = lambda report: "; ".join(
                    m for m in (first(report), finish(report)) if m)
            motions.send({"op": "comply", "id": running.command_id, "spec": spec})
            return running.command_id

    def _comply_outcome(self, report: dict) -> str:
        comply = report.get("comply")
        if comply is None:
            return report.get("message", "")
        held = (f"force {vector(comply['force'])} N, offset {vector(comply['offset'])} m "
                f"(tool frame)")
        why = report.get("message", "")
        if comply.get("panic") == PANIC_DRIVES_OFF and report["op"] == "failed":
            self.fault(alarms.PANIC, f"Comply {why}: panic stop code {PANIC_DRIVES_OFF}, "
                                     f"drives off")
        return f"{why}; {held}" if why else held

    # ---- helpers ----------------------------------------------------------------------------

    def _meant_to_touch(self, trajectories) -> tuple[AllowedContact, ...]:
        """The contacts a guarded or compliant motion is meant to make, allowed in its collision
        check: the tool, or the part it holds, with each body it would come within the margin
        of, in the order met (at most MAX_CONTACTS). Nothing else: the arm's links stay checked
        against everything, and the tool and the part against every other body."""
        scene = self.collisions
        carried = {scene.mounted, scene.held} - {None}
        model, allowed = scene.model(), []
        for trajectory in trajectories:
            while len(allowed) < MAX_CONTACTS:
                contact = check_motion(model, trajectory.positions, trajectory.dt,
                                       allow=allowed).contact
                if contact is None or contact.bodies[0] not in carried \
                        or contact.bodies[1] in ARM_LINKS:
                    break
                allowed.append(AllowedContact(f"meant to touch {contact.bodies[1]}",
                                              *contact.bodies))
        return tuple(allowed)

    def _ring_sensor(self, sensor: str) -> str:
        info = self.sensors.info(sensor)
        if not self.sensors.in_ring(sensor):
            raise ParamError(f"{sensor} is not read every cycle; guarded and compliant moves "
                             f"use the sensors the cycle reads")
        return info.kind

    def _tool_move(self, motion: np.ndarray, speed: float, start: np.ndarray | None = None):
        values = np.concatenate([motion, np.zeros(3)])
        motions = self.motions
        return motions.planner.move(motions.planning_start() if start is None else start,
                                    self.settings.current, Frame.TOOL, values, True, True, speed)


def _finite(what: str, *arrays) -> None:
    for values in arrays:
        if not np.all(np.isfinite(values)):
            raise ParamError(f"{what}: every value must be a finite number")


def _six(name: str, values: np.ndarray) -> np.ndarray:
    values = np.asarray(values, dtype=float)
    if values.size == 0:
        return np.zeros(6)
    if values.shape != (6,):
        raise ParamError(f"{name} takes 6 values (x, y, z, roll, pitch, yaw), got {values.size}")
    return values
