"""The check of a timed motion on its samples: how far each 4 ms sample exceeds the limits.

What the drives follow are the samples: velocities, accelerations (forward differences of the
velocities, and second differences of the positions, the arm held at rest before the first
sample and after the last), jerks (third differences, at rest around too) and, with a tool
path, the tool tip's linear and angular speeds and accelerations. Each excess is given as the
time stretch that would remove it if the whole motion were slowed uniformly: velocities scale
with 1/k, accelerations with 1/k^2, jerks with 1/k^3.
"""
from __future__ import annotations

import math
from typing import NamedTuple

import numpy as np

from .constraints import rotation_angle, rotation_vectors
from .trajectory import Limits

__all__ = ["Excess", "excess_per_sample"]


class Excess(NamedTuple):
    """Per sample (K,), each value the ratio to its limit of what ends at that sample (a
    difference counts at the last sample it takes), by how it scales with a slow-down:
    `speed` (joint and tool speeds, 1/k), `acceleration` (joint and tool, 1/k^2), `jerk`
    (1/k^3)."""
    speed: np.ndarray
    acceleration: np.ndarray
    jerk: np.ndarray

    def stretch(self) -> float:
        """The uniform time stretch that removes every excess (at most 1: none)."""
        return max(float(self.speed.max()), math.sqrt(float(self.acceleration.max())),
                   float(self.jerk.max()) ** (1.0 / 3.0))


def excess_per_sample(q: np.ndarray, v: np.ndarray, dt: float, limits: Limits,
                      tool_path=None) -> Excess:
    """The ratios of samples q, v (K, 6), every dt s, to the limits (see Excess)."""
    speed = np.max(np.abs(v) / limits.velocity, axis=1)
    acceleration, jerk = np.zeros(len(q)), np.zeros(len(q))
    if len(v) > 1:
        _at_last(acceleration, np.max(np.abs(np.diff(v, axis=0)) / dt / limits.acceleration,
                                      axis=1))
        held = np.concatenate([q[:1], q, q[-1:]])
        _at_last(acceleration, np.max(np.abs(held[2:] - 2.0 * held[1:-1] + held[:-2])
                                      / (dt * dt) / limits.acceleration, axis=1))
        if limits.jerk is not None:
            held = np.concatenate([q[:1], q[:1], q, q[-1:], q[-1:]])
            _at_last(jerk, np.max(np.abs(np.diff(held, 3, axis=0)) / dt**3 / limits.jerk,
                                  axis=1))
        if tool_path is not None:
            _tool(q, dt, limits, tool_path, speed, acceleration)
    return Excess(speed, acceleration, jerk)


def _tool(q, dt: float, limits: Limits, tool_path, speed, acceleration) -> None:
    """Adds the tool tip's speeds and accelerations (per-cycle steps, at rest before the first
    sample and after the last) to the ratios speed and acceleration (K,)."""
    moving = limits.linear_velocity or limits.angular_velocity
    accelerating = limits.linear_acceleration or limits.angular_acceleration
    if not (moving or accelerating):
        return
    poses = tool_path(q)
    linear = np.diff(poses[:, :3, 3], axis=0)
    if limits.linear_velocity:
        _at_last(speed, np.linalg.norm(linear, axis=1) / (dt * limits.linear_velocity))
    if limits.angular_velocity:
        _at_last(speed, rotation_angle(poses[:-1, :3, :3], poses[1:, :3, :3])
                 / (dt * limits.angular_velocity))
    if accelerating:
        # The change of step over dt^2 is the tip's acceleration as the drives make it.
        for limit, steps in ((limits.linear_acceleration, linear),
                             (limits.angular_acceleration,
                              rotation_vectors(poses[:-1, :3, :3], poses[1:, :3, :3]))):
            if limit:
                held = np.concatenate([np.zeros((1, 3)), steps, np.zeros((1, 3))])
                _at_last(acceleration,
                         np.linalg.norm(np.diff(held, axis=0), axis=1) / (dt * dt) / limit)


def _at_last(ratio: np.ndarray, values: np.ndarray) -> None:
    """ratio (K,) takes the larger of itself and values (L >= K - 1,), values[m] being a
    difference whose last sample is m + 1 (the samples held at rest past the end count at
    the last one)."""
    n = len(ratio) - 1
    np.maximum(ratio[1:], values[:n], out=ratio[1:])
    if len(values) > n:
        ratio[n] = max(ratio[n], float(values[n:].max()))
