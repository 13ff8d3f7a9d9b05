"""The last stage of the setpoints that no plan made in advance (jog, force settling,
compliance): each cycle, ruckig's jerk-limited, time-optimal way from where the commanded
joints are (position, velocity, acceleration) towards what the loop above wants, one cycle
along. Each cycle starts a new ruckig profile from the exact state the last one reached, so the
commanded motion is C2 with every joint's jerk, acceleration and velocity within the bounds
given: every discrete difference of the setpoints keeps them too (a third difference over
dt^3 is an average of the jerk). What the loop wants may step; the joints then follow it a few
cycles behind, never faster than the limits.

`VelocityTracker` follows a wanted velocity (jog: the joints' velocity, its direction kept
while the limits allow: phase synchronisation); `PositionTracker` follows a wanted position
(the planned setpoint shifted by a force loop), reaching it in one cycle when the limits allow.
"""
from __future__ import annotations

import numpy as np
from ruckig import (ControlInterface, InputParameter, OutputParameter, Result, Ruckig,
                    Synchronization)

_REST = 1e-9      # rad/s and rad/s^2 below which a tracker counts as at rest


class _Tracker:
    def __init__(self, position: np.ndarray, dt: float, velocity=None, acceleration=None):
        self.dt = dt
        self.position = np.array(position, dtype=float)
        self.velocity = np.zeros(6) if velocity is None else np.array(velocity, dtype=float)
        self.acceleration = (np.zeros(6) if acceleration is None
                             else np.array(acceleration, dtype=float))
        self._otg = Ruckig(6, dt)
        self._input = InputParameter(6)
        self._output = OutputParameter(6)

    @property
    def at_rest(self) -> bool:
        return bool(np.all(np.abs(self.velocity) < _REST)
                    and np.all(np.abs(self.acceleration) < _REST))

    def _step(self, velocity_limit, acceleration_limit, jerk_limit) -> np.ndarray:
        inp, out = self._input, self._output
        inp.current_position = self.position.tolist()
        inp.current_velocity = self.velocity.tolist()
        inp.current_acceleration = self.acceleration.tolist()
        inp.max_velocity = np.maximum(velocity_limit, np.abs(self.velocity)).tolist()
        inp.max_acceleration = list(acceleration_limit)
        inp.max_jerk = list(jerk_limit)
        result = self._otg.update(inp, out)
        if result not in (Result.Working, Result.Finished):
            raise RuntimeError(f"ruckig could not track: {result}")
        self.position = np.array(out.new_position)
        self.velocity = np.array(out.new_velocity)
        self.acceleration = np.array(out.new_acceleration)
        return self.position


class VelocityTracker(_Tracker):
    """Joint velocities towards a wanted one, within acceleration and jerk limits."""

    def __init__(self, position, dt: float):
        super().__init__(position, dt)
        self._input.control_interface = ControlInterface.Velocity
        self._input.synchronization = Synchronization.Phase

    def step(self, wanted: np.ndarray, acceleration: np.ndarray, jerk: np.ndarray,
             trend: np.ndarray | None = None) -> np.ndarray:
        """The next setpoint (rad) on the way to the velocity `wanted` (rad/s); `trend`
        (rad/s^2): how the wanted velocity changes, for a smooth one (followed without lag)."""
        self._input.target_velocity = list(wanted)
        self._input.target_acceleration = ([0.0] * 6 if trend is None else
                                           list(np.clip(trend, -acceleration, acceleration)))
        self._step(np.abs(wanted) + 1.0, acceleration, jerk)
        reached = ((np.abs(self.velocity - wanted) < _REST) & (np.abs(self.acceleration) < _REST)
                   if trend is None else np.zeros(6, dtype=bool))
        self.velocity[reached] = wanted[reached]         # exactly, once there (rounding)
        self.acceleration[reached] = 0.0
        return self.position


class PositionTracker(_Tracker):
    """Joint positions towards a wanted one (and its velocity), within the limits: at the
    wanted place after one cycle where the limits allow (a profile of at least one cycle,
    the joints arriving together: exact following of a wanted motion within the limits)."""

    def __init__(self, position, dt: float, velocity=None, acceleration=None):
        super().__init__(position, dt, velocity, acceleration)
        self._input.control_interface = ControlInterface.Position
        self._input.synchronization = Synchronization.Time
        self._input.minimum_duration = dt

    def step(self, wanted: np.ndarray, wanted_velocity: np.ndarray, velocity: np.ndarray,
             acceleration: np.ndarray, jerk: np.ndarray,
             wanted_acceleration: np.ndarray | None = None) -> np.ndarray:
        """The next setpoint (rad) towards `wanted` (rad) moving at `wanted_velocity` (rad/s)
        and, if given, changing it at `wanted_acceleration` (rad/s^2: without it a wanted
        motion that slows down is followed with an acceleration step to make up, and rings)."""
        self._input.target_position = list(wanted)
        self._input.target_velocity = list(np.clip(wanted_velocity, -velocity, velocity))
        self._input.target_acceleration = (
            [0.0] * 6 if wanted_acceleration is None
            else list(np.clip(wanted_acceleration, -acceleration, acceleration)))
        return self._step(velocity, acceleration, jerk)
