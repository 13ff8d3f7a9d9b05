"""Jog integration with its deadman, every cycle in the cycle process (seed 3.7.3, DESIGN 5).

A jog session turns velocity requests into setpoints: joint velocities as asked (JOINT), or
the tool tip's twist (linear m/s, angular rad/s about the tip, in base, world or tool axes)
through the tip Jacobian (pinocchio, damped near singularities). Every cycle the wanted joint
velocity is scaled down as a whole (so the direction holds) to the session's joint velocity
limits and to the manual-mode tip speed (ISO 10218-1: 250 mm/s), the velocity moves towards
it within the acceleration limits (the arm's full deceleration when stopping), and each joint
brakes so as to stop before the end of its range.

The deadman: no request for `deadman` cycles, or a request with the deadman released, brakes
the arm to rest along its direction at the arm's deceleration. Silence ends the session
("aborted", saying why); a released deadman only holds the arm until it is pressed again.

Collision seam: `keep_out(q) -> str | None`, when set, vetoes a setpoint (the arm brakes and
the session ends, saying why); the cell's collision checker (issue 11) plugs in here.

Messages (executor.py routes them):
  server -> cycle  {"op": "jog", "id", "limits": JogLimits, "tool_offset": (4, 4)}
                   {"op": "jog_velocity", "frame": "joint" | "base" | "world" | "tool",
                    "velocity": (6,) rad/s or (m/s, rad/s), "deadman": bool,
                    "world_rotation": (3, 3) world axes in base}
                   {"op": "jog_end"}   the client is done: brake, then "done"
                   "stop" / "abort" end the session the same way, reporting "aborted"
  cycle -> server  {"op": "started", "id", "wall_time"}, then "done" or "aborted" (with a
                   "message" saying why) or "failed" (drives off), as a motion's
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

import numpy as np

from landscape.server.tip_model import TipModel, damped_solve

MANUAL_TIP_SPEED = 0.25   # m/s, reduced speed for manual jogging (ISO 10218-1, 5.6)
RANGE_MARGIN = 1e-3       # rad: jogging stops this far inside the joint range


@dataclass(frozen=True)
class JogLimits:
    """(6,) arrays: velocity (rad/s, the set speed applied), acceleration (rad/s^2, the set
    acceleration), stop_acceleration (rad/s^2, the arm's own), lower / upper (rad, the joint
    range); tip_speed (m/s); deadman (cycles without a request before the arm stops)."""

    velocity: np.ndarray
    acceleration: np.ndarray
    stop_acceleration: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    tip_speed: float
    deadman: int


class JogIntegrator:
    def __init__(self, id: str, q: np.ndarray, limits: JogLimits, tip: TipModel,
                 tool_offset: np.ndarray, dt: float):
        self.id, self.limits, self.tip, self.dt = id, limits, tip, dt
        self.tool_offset = tool_offset
        self.q = np.array(q, dtype=float)
        self.qd = np.zeros(6)
        self.keep_out: Callable[[np.ndarray], str | None] | None = None
        self._frame = "joint"
        self._velocity = np.zeros(6)
        self._pressed = False
        self._world = np.eye(3)
        self._silent = 0              # cycles since the last request
        self.ending: tuple[str, str] | None = None   # (report, message) once it must stop

    def command(self, msg: dict) -> None:
        self._silent = 0
        self._frame = msg["frame"]
        self._velocity = np.asarray(msg["velocity"], dtype=float)
        self._pressed = bool(msg["deadman"])
        self._world = np.asarray(msg.get("world_rotation", np.eye(3)), dtype=float)

    def end(self, how: str, message: str = "") -> None:
        if self.ending is None:
            self.ending = (how, message)

    @property
    def finished(self) -> bool:
        return self.ending is not None and not np.any(self.qd)

    def step(self) -> tuple[np.ndarray, np.ndarray]:
        """The next setpoint (position rad, velocity rad/s)."""
        limits, dt = self.limits, self.dt
        self._silent += 1
        if self._silent > limits.deadman:
            self.end("aborted", f"deadman: no jog request for {limits.deadman * dt * 1000:g} ms;"
                                f" the arm stopped")
        stopping = self.ending is not None or not self._pressed
        wanted = np.zeros(6) if stopping else self._wanted()
        change = wanted - self.qd
        accel = limits.stop_acceleration if stopping else limits.acceleration
        excess = float(np.max(np.abs(change) / (accel * dt)))
        if excess > 1.0:
            change /= excess
        qd = self._within_range(self.qd + change)
        q = self.q + qd * dt
        if self.keep_out is not None and (why := self.keep_out(q)) is not None:
            self.end("aborted", why)
        self.q, self.qd = np.clip(q, limits.lower, limits.upper), qd
        return self.q, self.qd

    def _wanted(self) -> np.ndarray:
        """Joint velocities for the request, within the speed limits, direction kept."""
        limits = self.limits
        if self._frame == "joint":
            qd = self._velocity.copy()
        else:
            twist = self._velocity
            tip = self.tip
            tip.set_tool(self.tool_offset)
            if self._frame == "world":
                rotation = self._world
            elif self._frame == "tool":
                rotation = tip.forward(self.q)[:3, :3]
            else:
                rotation = np.eye(3)
            twist = np.concatenate([rotation @ twist[:3], rotation @ twist[3:]])
            qd = damped_solve(tip.jacobian(self.q), twist)
        tip_speed = float(np.linalg.norm(self._tip_jacobian()[:3] @ qd))
        scale = max(1.0, float(np.max(np.abs(qd) / limits.velocity)),
                    tip_speed / limits.tip_speed)
        return qd / scale

    def _tip_jacobian(self) -> np.ndarray:
        self.tip.set_tool(self.tool_offset)
        return self.tip.jacobian(self.q)

    def _within_range(self, qd: np.ndarray) -> np.ndarray:
        """Each joint slow enough to stop before its range ends (at the arm's deceleration)."""
        limits = self.limits
        room = np.where(qd > 0, limits.upper - RANGE_MARGIN - self.q,
                        self.q - (limits.lower + RANGE_MARGIN))
        # Reaching the limit within this cycle's move: as fast as still stops in the room.
        top = np.sqrt(2.0 * limits.stop_acceleration * np.maximum(room, 0.0))
        return np.clip(qd, -top, top)
