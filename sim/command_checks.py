"""What a simulated CS8's drives accept in a cycle's command (LLI 5.3.6): every joint within its
range, its maximum velocity, the step its velocity allows in one cycle, and a change of
velocity a drive can follow (acceleration_factor * max acceleration * cycle time); torques
finite, clipped to the drives' effort. An invalid command is never applied (cs8.py disables
the drives), and the refusal says which joint and what is wrong.
"""
from __future__ import annotations

import math

import numpy as np

from landscape.robot.arm import ArmModel
from landscape.robot.cell import ControllerSpec
from landscape.robot.controller import JointCmd

_SLACK = 1e-9                  # rad, rad/s: rounding allowance of the command checks


class CommandChecks:
    def __init__(self, arm: ArmModel, spec: ControllerSpec, effort: list[float]):
        # Limits, (6,) arrays.
        self._lower, self._upper = arm.lower, arm.upper
        self._vmax = np.array(arm.max_velocity)
        self._max_step = self._vmax * spec.cycle_time
        self._max_dvel = spec.acceleration_factor * np.array(arm.max_acceleration) * spec.cycle_time
        # The per-joint limits of the command checks, as plain lists (numpy is slow on 6
        # values): (min, max, max |vel|, max |pos step|, max |vel step|, max |torque|), with the
        # rounding allowance the checks grant.
        self._limits = list(zip(self._lower.tolist(), self._upper.tolist(),
                                (self._vmax + _SLACK).tolist(), (self._max_step + _SLACK).tolist(),
                                (self._max_dvel + _SLACK).tolist(), effort))

    def check(self, cmd: JointCmd, last_pos: list, last_vel: list) -> tuple[list, list, list] | str:
        """The command as the drives take it, (pos, vel, clipped torque) lists, from the last
        one taken (last_pos, last_vel); or what is wrong with it."""
        pos, vel, tau = cmd.pos, cmd.vel, cmd.torque_ffw
        if pos.shape != (6,) or vel.shape != (6,) or tau.shape != (6,):
            return f"a command needs 6 values per field, got {pos.shape}, {vel.shape}, {tau.shape}"
        pos, vel, tau = pos.tolist(), vel.tolist(), tau.tolist()
        clipped = []
        # NaN fails every comparison, so these checks reject it too.
        for i, (lo, hi, vmax, step, dvel, effort) in enumerate(self._limits):
            p, v, t = pos[i], vel[i], tau[i]
            if not (lo <= p <= hi and -vmax <= v <= vmax and -step <= p - last_pos[i] <= step
                    and -dvel <= v - last_vel[i] <= dvel and -math.inf < t < math.inf):
                return self._explain(i, p, v, t, last_pos, last_vel)
            clipped.append(-effort if t < -effort else effort if t > effort else t)
        return pos, vel, clipped

    def _explain(self, i: int, p: float, v: float, t: float, last_pos, last_vel) -> str:
        """What is wrong with joint i's command (position p, velocity v, torque t)."""
        j, lo, hi = i + 1, self._lower[i], self._upper[i]
        if not (math.isfinite(p) and math.isfinite(v) and math.isfinite(t)):
            return f"joint {j} command holds NaN or infinite values"
        if not lo <= p <= hi:
            return f"joint {j} position {p:.6f} rad is outside its range [{lo:.6f}, {hi:.6f}] rad"
        if abs(v) > self._vmax[i] + _SLACK:
            return (f"joint {j} velocity {v:.6f} rad/s exceeds its maximum "
                    f"{self._vmax[i]:.6f} rad/s")
        step = abs(p - last_pos[i])
        if step > self._max_step[i] + _SLACK:
            return (f"joint {j} position changes by {step:.6f} rad in one cycle, more than its "
                    f"maximum velocity allows ({self._max_step[i]:.6f} rad)")
        change = abs(v - last_vel[i])
        return (f"joint {j} velocity changes by {change:.6f} rad/s in one cycle, more than a "
                f"drive can follow ({self._max_dvel[i]:.6f} rad/s)")
