"""Jog integration with its deadman, every cycle in the cycle process (seed 3.7.3, DESIGN 5).

A jog session turns velocity requests into setpoints. A JOINT jog moves the joints at the
velocities asked. A Cartesian jog (base, world or tool axes) moves the tool tip at the twist
asked (linear m/s, angular rad/s about the tip): the tip follows a reference pose that
advances with the twist, the joints through the tip Jacobian (pinocchio, damped near
singularities) with a correction towards the reference (closed-loop inverse kinematics), so
the tip keeps its line and its orientation instead of drifting.

Every cycle the wanted motion is scaled down as a whole (its direction holds) to the joint jog
speeds and to the manual-mode tip speed (ISO 10218-1: 250 mm/s); the velocity moves towards it
within the acceleration limits, at the arm's full deceleration when stopping; and each joint
brakes so as to stop before the end of its range. The joints follow that velocity through a
jerk-limited tracker (jerk_tracker.py: the set jerk, the arm's when stopping), so a jog, its
stops and its deadman never step an acceleration (issue 30). A tracker speeding up cannot stop
speeding up at once (a|a|/2j more per joint): a step after which the tip could no longer level
off within the manual speed is taken levelling off instead, and a step whose tip would still
move faster than the manual speed is shortened to it (its jerk then may step: the speed is the
safety limit). Without this the joints, lagging a Cartesian jog's line where their
accelerations cannot keep up, then racing its correction, commanded the tip at 286 mm/s.

The deadman: no request for `deadman` cycles, or a request with the deadman released, brakes
the arm to rest along its direction. Silence ends the session ("aborted", saying why); a
released deadman only holds the arm until it is pressed again.

Near obstacles (a velocity damper): the server's clearance guard (jog_guard.py) sends the
gradient of the arm's clearance in joint space (m/rad) and the rate (m/s) at which the arm may
still close it; every cycle a motion whose approach (-gradient . qd) exceeds that rate is
scaled down to it, within the arm's full deceleration, while any motion that keeps or opens the
clearance stays free. The guard's figures hold for STALE_CYCLES only: a late guard (its thread
stalled) allows no approach at all, and with no figures of its own (far from everything, or
none yet) the arm is held until it speaks again.

Messages (executor.py routes them):
  server -> cycle  {"op": "jog", "id", "limits": JogLimits, "tool_offset": (4, 4),
                    "guarded": bool (a clearance guard reports every few cycles)}
                   {"op": "jog_velocity", "frame": "joint" | "base" | "world" | "tool",
                    "velocity": (6,) rad/s or (m/s, rad/s), "deadman": bool,
                    "world_rotation": (3, 3) world axes in base}
                   {"op": "jog_clearance", "gradient": (6,) m/rad or None, "rate": m/s}
                   {"op": "jog_end"}   the client is done: brake, then "done"
                   "stop" / "abort" end the session the same way, reporting "aborted"
  cycle -> server  {"op": "started", "id", "wall_time"}, then "done" or "aborted" (with a
                   "message" saying why) or "failed" (drives off), as a motion's
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from landscape.server.cycle.jerk_tracker import VelocityTracker
from landscape.server.cycle.tip_model import TipModel, damped_solve

MANUAL_TIP_SPEED = 0.25   # m/s, reduced speed for manual jogging (ISO 10218-1, 5.6)
RANGE_MARGIN = 1e-3       # rad: jogging stops this far inside the joint range
TRACKING = 0.2            # of the tip's distance to its reference made good per cycle
HEADROOM = 0.95           # of the speed limits a Cartesian jog asks for: the rest corrects
                          # (and the joints' jerk-limited tracking overshoots by up to 3 %)
ON_REFERENCE = 1e-7       # m and rad: a stopping Cartesian jog's tip counts as on its line
STALE_CYCLES = 10         # a clearance older than this is not trusted (the guard sends every 2)


@dataclass(frozen=True)
class JogLimits:
    """(6,) arrays: velocity (rad/s, the set speed applied), acceleration (rad/s^2, the set
    acceleration), stop_acceleration (rad/s^2, the arm's own), lower / upper (rad, the joint
    range); (2,) cartesian_acceleration and cartesian_stop: linear m/s^2 and angular rad/s^2
    of the tip, set and the arm's; tip_speed (m/s); deadman (cycles without a request before
    the arm stops); jerk and stop_jerk (6,) rad/s^3, the set and the arm's."""

    velocity: np.ndarray
    acceleration: np.ndarray
    stop_acceleration: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    cartesian_acceleration: np.ndarray
    cartesian_stop: np.ndarray
    tip_speed: float
    deadman: int
    jerk: np.ndarray
    stop_jerk: np.ndarray


class JogIntegrator:
    def __init__(self, id: str, q: np.ndarray, limits: JogLimits, tip: TipModel,
                 tool_offset: np.ndarray, dt: float, guarded: bool = False):
        self.id, self.limits, self.tip, self.dt = id, limits, tip, dt
        self.tool_offset = tool_offset
        self.q = np.array(q, dtype=float)
        self.qd = np.zeros(6)
        self._tracker = VelocityTracker(self.q, dt)
        self._twist_tracker = VelocityTracker(np.zeros(6), dt)   # Cartesian jogs' twist
        self._wanted: np.ndarray | None = None    # the joint velocity wanted last cycle
        self._clearance: tuple[np.ndarray, float] | None = None   # gradient (6,) m/rad, m/s
        self._clearance_age = 0 if guarded else None   # cycles since the guard's figures
        self.ending: tuple[str, str] | None = None   # (report, message) once it must stop
        self._frame = "joint"
        self._velocity = np.zeros(6)
        self._pressed = False
        self._world = np.eye(3)
        self._silent = 0              # cycles since the last request
        self._twist = np.zeros(6)     # the tip's, Cartesian jogs: m/s, rad/s in base axes
        self._reference: np.ndarray | None = None   # where the tip should be, Cartesian jogs

    def command(self, msg: dict) -> None:
        self._silent = 0
        self._frame = msg["frame"]
        self._velocity = np.asarray(msg["velocity"], dtype=float)
        self._pressed = bool(msg["deadman"])
        self._world = np.asarray(msg.get("world_rotation", np.eye(3)), dtype=float)

    def keep_clear(self, msg: dict) -> None:
        gradient = msg["gradient"]
        self._clearance = None if gradient is None else (
            np.asarray(gradient, dtype=float), max(0.0, float(msg["rate"])))
        self._clearance_age = 0

    def end(self, how: str, message: str = "") -> None:
        if self.ending is None:
            self.ending = (how, message)

    @property
    def finished(self) -> bool:
        return self.ending is not None and self._tracker.at_rest

    def step(self) -> tuple[np.ndarray, np.ndarray]:
        """The next setpoint (position rad, velocity rad/s)."""
        limits, dt = self.limits, self.dt
        self._silent += 1
        if self._silent > limits.deadman:
            self.end("aborted", f"deadman: no jog request for {limits.deadman * dt * 1000:g} ms;"
                                f" the arm stopped")
        # A guard fallen silent with nothing near holds the arm: braking as a stop does.
        stopping = self.ending is not None or not self._pressed or self._guard_silent()
        self.tip.set_tool(self.tool_offset)
        if self._frame == "joint":
            self._reference = None
            qd = self._joint_step(stopping)
        else:
            qd = self._cartesian_step(stopping)
        cleared = self._clear_of_obstacles(qd)
        limited = self._within_range(cleared)
        if not np.array_equal(limited, cleared):
            self._reference = None    # a joint range decides: off the line
        elif self._reference is not None and not np.array_equal(cleared, qd):
            self._slowed(cleared, qd)  # an obstacle slows the jog: along its line
        # A joint jog speeds up within the set limits; braking, and following a Cartesian
        # jog's joints (its twist keeps the set limits), within the arm's.
        braking = (stopping or self._frame != "joint"
                   or np.any(np.abs(limited) < np.abs(self.qd) - 1e-12))
        tracker = self._tracker
        # A Cartesian jog's joint velocities change smoothly: followed with their trend.
        trend = None
        if self._frame != "joint" and not stopping and self._wanted is not None:
            trend = (limited - self._wanted) / dt
        self._wanted = limited
        accel = limits.stop_acceleration if braking else limits.acceleration
        jerk = limits.stop_jerk if braking else limits.jerk
        before = self.q, self.qd, tracker.acceleration.copy()
        tracker.step(limited, accel, jerk, trend)
        if self._committed_tip_speed(jerk) > limits.tip_speed:
            # Too fast to stop speeding up within the manual speed (a jerk-limited tracker
            # takes a|a|/2j more): level off where it is instead, and let the line catch up.
            tracker.position, tracker.velocity, tracker.acceleration = before
            tracker.step(before[1], accel, jerk)
        self._within_tip_speed(before[0])
        self.q, self.qd = tracker.position.copy(), tracker.velocity.copy()
        return self.q, self.qd

    def _committed_tip_speed(self, jerk: np.ndarray) -> float:
        """The tip speed (m/s) the joints reach at least before their accelerations, brought
        to zero at the jerk limit, let them level off (each joint a|a|/2j past its velocity)."""
        tracker = self._tracker
        committed = tracker.velocity + tracker.acceleration * np.abs(tracker.acceleration) / (
            2.0 * jerk)
        return float(np.linalg.norm(self.tip.jacobian(tracker.position)[:3] @ committed))

    def _within_tip_speed(self, q: np.ndarray) -> None:
        """The last guard of the manual speed: a step whose tip would move faster than it
        (the levelling off above is a prediction, the joints' synchronised jerks may differ)
        is shortened to it, its velocity alike. Its jerk may then step: speed is the safety
        limit here."""
        tracker, tip, dt = self._tracker, self.tip, self.dt
        start = tip.forward(q)[:3, 3].copy()
        for _ in range(3):   # the tip's chord is near linear in the step: one pass, or two
            speed = float(np.linalg.norm(tip.forward(tracker.position)[:3, 3] - start)) / dt
            if speed <= self.limits.tip_speed:
                return
            factor = self.limits.tip_speed / speed * (1.0 - 1e-6)
            tracker.position = q + (tracker.position - q) * factor
            tracker.velocity = tracker.velocity * factor
            tracker.acceleration = (tracker.velocity - self.qd) / dt

    def _clear_of_obstacles(self, qd: np.ndarray) -> np.ndarray:
        """qd scaled down as a whole (its direction holds: the arm does not slide along what
        it nears) so that its approach to the nearest obstacle is at most the rate allowed,
        reached within the arm's full deceleration. Figures older than STALE_CYCLES allow no
        approach (no figures at all: _guard_silent)."""
        clearance = self._clearance
        if clearance is None:
            return qd
        if self._clearance_age is not None and self._clearance_age > STALE_CYCLES:
            clearance = (clearance[0], 0.0)
        gradient, rate = clearance
        approach = -float(gradient @ qd)
        if approach <= rate:
            return qd
        return qd * (rate / approach)

    def _guard_silent(self) -> bool:
        """Whether the guard's last figures, which said nothing is near, are too old to trust
        (they age a cycle per call); figures of something near are _clear_of_obstacles'."""
        if self._clearance_age is None:
            return False
        self._clearance_age += 1
        return self._clearance_age > STALE_CYCLES and self._clearance is None

    # ---- joint jogs -------------------------------------------------------------------------

    def _joint_step(self, stopping: bool) -> np.ndarray:
        return np.zeros(6) if stopping else self._velocity / self._scale(self._velocity)

    # ---- Cartesian jogs ---------------------------------------------------------------------

    def _cartesian_step(self, stopping: bool) -> np.ndarray:
        limits, dt, tip = self.limits, self.dt, self.tip
        jacobian = tip.jacobian(self.q).copy()
        twist = self._twist_tracker
        if self._reference is None:   # (re)anchored where the tip is, moving as it moves
            self._reference = tip.forward(self.q).copy()
            twist.velocity = jacobian @ self.qd
            twist.acceleration = np.zeros(6)
        if stopping:
            # At rest on the reference; the joints, which follow the twist's braking a little
            # behind, are brought back onto it first.
            if (twist.at_rest and not np.any(twist.velocity)
                    and np.max(np.abs(tip.pose_error(self._reference))) < ON_REFERENCE):
                return np.zeros(6)
            wanted, accel = np.zeros(6), np.repeat(limits.cartesian_stop, 3)
        else:
            wanted = self._base_twist()
            wanted = wanted / self._scale(damped_solve(jacobian, wanted), jacobian, HEADROOM)
            accel = np.repeat(limits.cartesian_acceleration, 3)
        # The twist ramps its acceleration up as the joints do theirs (the same ramp time).
        ramp = float(np.max(limits.stop_acceleration / limits.stop_jerk))
        twist.step(wanted, accel, accel / ramp)
        self._twist = twist.velocity.copy()
        reference = self._reference
        # The tip model's last pose is the tip's now (every call above was at self.q).
        correction = TRACKING / dt * tip.pose_error(reference)   # before it moves on
        reference[:3, 3] += self._twist[:3] * dt
        reference[:3, :3] = pin.exp3(self._twist[3:] * dt) @ reference[:3, :3]
        qd = damped_solve(jacobian, self._twist + correction)
        return qd / self._scale(qd, jacobian)   # the correction too stays within the limits

    def _slowed(self, cleared: np.ndarray, qd: np.ndarray) -> None:
        """A Cartesian jog slowed by the guard (qd scaled down as a whole to `cleared`): its
        twist and this cycle's step of its line's reference scaled alike, so that the tip
        keeps to the line (the joints' tracking lags a little; the line's correction makes
        it up)."""
        factor = float(cleared @ qd / max(float(qd @ qd), 1e-300))
        twist, reference = self._twist_tracker, self._reference
        back = (factor - 1.0) * self._twist * self.dt
        reference[:3, 3] += back[:3]
        reference[:3, :3] = pin.exp3(back[3:]) @ reference[:3, :3]
        twist.velocity = twist.velocity * factor
        twist.acceleration = twist.acceleration * factor
        self._twist = twist.velocity.copy()

    def _base_twist(self) -> np.ndarray:
        """The request's twist in base axes."""
        if self._frame == "world":
            rotation = self._world
        elif self._frame == "tool":
            rotation = self.tip.forward(self.q)[:3, :3]
        else:
            rotation = np.eye(3)
        return np.concatenate([rotation @ self._velocity[:3], rotation @ self._velocity[3:]])

    # ---- limits -----------------------------------------------------------------------------

    def _scale(self, qd: np.ndarray, jacobian: np.ndarray | None = None,
               share: float = 1.0) -> float:
        """How much a joint velocity is too fast for `share` of the joint jog speeds and of
        the manual tip speed (1: not at all)."""
        limits = self.limits
        if jacobian is None:
            jacobian = self.tip.jacobian(self.q)
        tip_speed = float(np.linalg.norm(jacobian[:3] @ qd))
        return max(1.0, float(np.max(np.abs(qd) / limits.velocity)) / share,
                   tip_speed / limits.tip_speed / share)

    def _within_range(self, qd: np.ndarray) -> np.ndarray:
        """Each joint slow enough to stop before its range ends (at the arm's deceleration and
        jerk, after the tracker's lag of one acceleration ramp)."""
        limits = self.limits
        a, j = limits.stop_acceleration, limits.stop_jerk
        room = np.where(qd > 0, limits.upper - RANGE_MARGIN - self.q,
                        self.q - (limits.lower + RANGE_MARGIN))
        room = np.maximum(room - np.abs(self.qd) * (a / j + self.dt), 0.0)
        # The stop from v with the deceleration ramped up: v^2 / 2a + v a / 2j <= room.
        top = 0.5 * (np.sqrt((a * a / j) ** 2 + 8.0 * a * room) - a * a / j)
        return np.clip(qd, -top, top)

