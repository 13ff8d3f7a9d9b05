"""CRCL guards (the 2021 revision: a Guard on a command ends it when a sensor crosses a limit)
as the device's guarded move, MoveReact.

MoveReact moves the tool tip in a straight line without turning it and stops at the arm's full
deceleration, in the controller's cycle (4 ms), when a watched component of one sensor crosses
its threshold: the force sensor's Fx, Fy, Fz (tool frame, at the tip; it is tared as the move
starts), or the range sensor's distance. Its collision check lets the tool meet what it is
meant to touch. So a guarded MoveTo is carried out when its pose keeps the tool's orientation;
its guards become MoveReact's thresholds:

- INCREASE_OVER_LIMIT / DECREASE_BEYOND_LIMIT: the reading's change since the start, +- the
  limit;
- OVER_MAX / UNDER_MIN: the limit itself, less the reading at the start (the force sensor counts
  from its tare at the start).

Limits are in the session's force units (the force sensor) or length units (the range sensor).
A guard that triggers ends the command Done (ErrorOnTrigger: Error), stopped where it
triggered; RequireTrigger makes a command that ends without a trigger an Error. The device
checks every cycle, as often as any RecheckTimeMicroSeconds can ask of it; CheckCount,
LastCheckTime and LastCheckValue mean nothing in a command (the schema says so). Guards on
torques, on two sensors, twice on one component, or on any other command cannot be carried out
by the device's guarded move: they are refused, saying so, before anything moves.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from landscape.gateway import model as m
from landscape.gateway import poses
from landscape.gateway.device_units import DeviceUnits
from landscape.gateway.errors import CrclError

FORCE_SENSOR, RANGE_SENSOR = "force_sensor", "laser_standoff_sensor"
FORCE_AXES = {"Fx": 0, "Fy": 1, "Fz": 2}
RANGE_FIELDS = (None, "ScalarValue", "Distance")
TRIGGER_DISTANCE = 0.001   # m short of the goal: a move that ended there was stopped by a guard


@dataclass(frozen=True)
class GuardReport:
    """What GuardsStatuses says of the last guarded command: its guards, whether one
    triggered, when the arm stopped (unix us), the guarded reading then (the session's units)
    and the tool's pose (SI, in CRCL's frame)."""

    guards: tuple[m.Guard, ...]
    trigger_count: int = 0
    stop_time_us: int = 0
    value: float | None = None
    pose: np.ndarray | None = None


def refuse(command: m.Command) -> None:
    """CrclError unless the device can watch `command`'s guards (a MoveTo's)."""
    if not isinstance(command, m.MoveTo):
        raise CrclError(f"Guard on {command.KIND}: guards are carried out on MoveTo only (the "
                        f"device's guarded move, MoveReact, moves the tool in a straight line "
                        f"without turning it); send {command.KIND} without Guard elements")


def sensor_of(guards: tuple[m.Guard, ...]) -> str:
    """The one sensor the guards watch; CrclError if they name several, or one the device's
    guarded move cannot watch."""
    sensors = {g.sensor_id for g in guards}
    if len(sensors) > 1:
        raise CrclError(f"Guard: the device's guarded move watches one sensor; these guards name "
                        f"{', '.join(sorted(sensors))}")
    (sensor,) = sensors
    if sensor not in (FORCE_SENSOR, RANGE_SENSOR):
        raise CrclError(f"Guard: SensorID {sensor!r} is none the device's guarded move watches "
                        f"({FORCE_SENSOR}: Fx, Fy, Fz; {RANGE_SENSOR})")
    return sensor


def _where(guard: m.Guard) -> str:
    return f"{guard.sensor_id} {guard.sub_field}" if guard.sub_field else guard.sensor_id


def _axis(guard: m.Guard) -> int:
    if guard.sensor_id == RANGE_SENSOR:
        if guard.sub_field not in RANGE_FIELDS:
            raise CrclError(f"Guard: {RANGE_SENSOR} has one value; SubField "
                            f"{guard.sub_field!r} names none")
        return 0
    if guard.sub_field not in FORCE_AXES:
        raise CrclError(f"Guard: SubField {guard.sub_field!r} of {FORCE_SENSOR}: the device's "
                        f"guarded move watches the forces Fx, Fy and Fz (not the torques)")
    return FORCE_AXES[guard.sub_field]


def thresholds(session, guards: tuple[m.Guard, ...], start: np.ndarray) -> list[float]:
    """MoveReact's three thresholds (SI) for `guards`, the sensor reading `start` (SI) before
    the move."""
    force = sensor_of(guards) == FORCE_SENSOR
    units, out = session.settings.units, [0.0, 0.0, 0.0]
    for guard in guards:
        axis, where = _axis(guard), _where(guard)
        if out[axis]:
            raise CrclError(f"Guard: two guards on {where}: the device's guarded move watches "
                            f"each value once")
        limit = units.force_si(guard.limit_value) if force else units.length_si(guard.limit_value)
        if not math.isfinite(start[axis]):
            raise CrclError(f"Guard: {where} sees nothing in its range to start from")
        now = 0.0 if force else float(start[axis])      # the force sensor is tared at the start
        absolute = limit - (float(start[axis]) - now)   # a fixed limit, as the move counts
        target = {"INCREASE_OVER_LIMIT": now + abs(limit), "DECREASE_BEYOND_LIMIT": now - abs(limit),
                  "OVER_MAX": absolute, "UNDER_MIN": absolute}[guard.limit_type]
        rising = guard.limit_type in ("INCREASE_OVER_LIMIT", "OVER_MAX")
        if target == 0.0 or (target <= now if rising else target >= now):
            raise CrclError(f"Guard {guard.limit_type} {guard.limit_value:g} on {where}: the "
                            f"reading is there already")
        out[axis] = target
    return out


def tool_motion(here: np.ndarray, goal: np.ndarray, turn_tolerance: float) -> np.ndarray:
    """MoveReact's motion (tool frame, m) from the tool pose `here` to `goal` (SI, base
    frame); CrclError if the goal turns the tool."""
    now, there = poses.matrix(here), poses.matrix(goal)
    turn = float(np.linalg.norm(pin.log3(now[:3, :3].T @ there[:3, :3])))
    if turn > turn_tolerance:
        raise CrclError(f"a guarded MoveTo moves in a straight line without turning the tool "
                        f"(the device's guarded move, MoveReact): this pose turns it by "
                        f"{math.degrees(turn):.3g} degrees")
    return now[:3, :3].T @ (there[:3, 3] - now[:3, 3])


def reading_si(reply) -> np.ndarray:
    """A GetSensorReading reply's values in SI (lengths of a range; forces are N)."""
    values = np.array(reply.current_data, dtype=float)
    if len(values) == 1:
        values *= DeviceUnits.of(reply.units).meters
    return values


def outcome(session, guards: tuple[m.Guard, ...], limits: list[float], goal_base: np.ndarray,
            end_base: np.ndarray, reading: np.ndarray, ended: float) -> str:
    """The Done description of a guarded move with MoveReact thresholds `limits` that ended at
    `end_base` (SI, base frame) with the sensor at `reading` (SI; a force counts from the tare
    at the start) at unix time `ended`; the session's GuardReport made; CrclError where the
    guards' flags make one."""
    triggered = float(np.linalg.norm(end_base[:3] - goal_base[:3])) > TRIGGER_DISTANCE
    report = GuardReport(guards)
    if triggered:   # the guard nearest its limit is the one that stopped the arm
        guard = max(guards, key=lambda g: reading[_axis(g)] / limits[_axis(g)])
        units, force = session.settings.units, guard.sensor_id == FORCE_SENSOR
        value = (units.force_out if force else units.length_out)(reading[_axis(guard)])
        report = GuardReport(guards, 1, int(ended * 1e6), value,
                             poses.to_workstation(end_base, session.settings.frame))
    session.guard_report = report
    if not triggered:
        if any(g.require_trigger for g in guards):
            raise CrclError("its guard never triggered: the motion ended at its pose "
                            "(RequireTrigger)")
        return ""
    said = (f"stopped by its guard {guard.limit_type} on {_where(guard)}: it read "
            f"{report.value:.4g} {units.force if force else units.length}")
    if any(g.error_on_trigger for g in guards):
        raise CrclError(f"{said} (ErrorOnTrigger)")
    return said
