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

import numpy as np

from .constraints import rotation_angle, rotation_vectors
from .trajectory import Limits

__all__ = ["Excess", "excess_per_sample"]


class Excess:
    """The ratios of the samples to their limits, by how they scale with a slow-down: speeds
    (joint and tool, 1/k), accelerations (joint and tool, 1/k^2), jerks (1/k^3). Kept as the
    checks gave them, (L,) or (L, 6) each, value m of a difference ending at sample m + 1:
    `stretch` takes their maxima, the per-sample ratios are worked out only when asked for."""

    def __init__(self, samples: int):
        self.samples = samples
        self.parts: dict[str, list[np.ndarray]] = {"speed": [], "acceleration": [], "jerk": []}

    def stretch(self) -> float:
        """The uniform time stretch that removes every excess (at most 1: none)."""
        peak = {kind: max((float(p.max()) for p in parts if p.size), default=0.0)
                for kind, parts in self.parts.items()}
        return max(peak["speed"], math.sqrt(peak["acceleration"]), peak["jerk"] ** (1.0 / 3.0))

    def per_sample(self, kind: str) -> np.ndarray:
        """(K,) the largest ratio of `kind` ending at each sample (the samples held at rest
        past the end count at the last one)."""
        ratio = np.zeros(self.samples)
        n = self.samples - 1
        for part in self.parts[kind]:
            values = part.max(axis=1) if part.ndim == 2 else part
            if n > 0 and len(values):
                np.maximum(ratio[1:], values[:n], out=ratio[1:])
                ratio[n] = max(ratio[n], float(values[n - 1:].max()))
        return ratio


def excess_per_sample(q: np.ndarray, v: np.ndarray, dt: float, limits: Limits,
                      tool_path=None) -> Excess:
    """The ratios of samples q, v (K, 6), every dt s, to the limits (see Excess)."""
    excess = Excess(len(q))
    speed, acceleration = excess.parts["speed"], excess.parts["acceleration"]
    speed.append(np.abs(v[1:]) / limits.velocity)         # v[0]: at rest
    if len(v) > 1:
        acceleration.append(np.abs(np.diff(v, axis=0)) / (dt * limits.acceleration))
        held = np.concatenate([q[:1], q, q[-1:]])
        acceleration.append(np.abs(held[2:] - 2.0 * held[1:-1] + held[:-2])
                            / (dt * dt * limits.acceleration))
        if limits.jerk is not None:
            held = np.concatenate([q[:1], q[:1], q, q[-1:], q[-1:]])
            excess.parts["jerk"].append(np.abs(np.diff(held, 3, axis=0)) / (dt**3 * limits.jerk))
        if tool_path is not None:
            _tool(q, dt, limits, tool_path, speed, acceleration)
    return excess


def _tool(q, dt: float, limits: Limits, tool_path, speed: list, acceleration: list) -> None:
    """Adds the tool tip's speed and acceleration ratios (per-cycle steps, at rest before the
    first sample and after the last) to the lists speed and acceleration."""
    moving = limits.linear_velocity or limits.angular_velocity
    accelerating = limits.linear_acceleration or limits.angular_acceleration
    if not (moving or accelerating):
        return
    poses = tool_path(q)
    linear = np.diff(poses[:, :3, 3], axis=0)
    if limits.linear_velocity:
        speed.append(np.linalg.norm(linear, axis=1) / (dt * limits.linear_velocity))
    if limits.angular_velocity:
        speed.append(rotation_angle(poses[:-1, :3, :3], poses[1:, :3, :3])
                     / (dt * limits.angular_velocity))
    if accelerating:
        # The change of step over dt^2 is the tip's acceleration as the drives make it.
        for limit, steps in ((limits.linear_acceleration, linear),
                             (limits.angular_acceleration,
                              rotation_vectors(poses[:-1, :3, :3], poses[1:, :3, :3]))):
            if limit:
                held = np.concatenate([np.zeros((1, 3)), steps, np.zeros((1, 3))])
                acceleration.append(np.linalg.norm(np.diff(held, axis=0), axis=1)
                                    / (dt * dt * limit))
