"""The device server's cyclic function: the per-cycle part of the device, in the cycle process.

Every cycle (LLI 5.3.10) it reads the feedback, takes the server's messages, computes the
setpoint and sets it. While the drives are not enabled it commands the measured position, so
that enabling starts from where the arm is and never jumps (LLI 5.3.3).

A motion is a timed trajectory sampled at the cycle time (motion/trajectory.py), played one
sample per cycle. Stopping and resuming scale time, not space: a play rate r in [0, 1] advances
the sample index by r per cycle, so the arm slows down and speeds up along the planned path and
never leaves it (seed 3.6). Played at rate r, joint j moves at v_j r and accelerates at
a_j r^2 + v_j dr/dt (v, a: the trajectory's at rate 1); each cycle the rate changes as fast as
keeping every joint's acceleration within its limit allows. Keeping the rate always qualifies
(the trajectory is within the limits at r = 1, so at any r <= 1), so a stop or a restart never
asks more of a joint than its limit.

Messages, plain dicts (picklable, so they cross the process boundary):
  server -> cycle  {"op": "run", "id": str, "acceleration": (6,) rad/s^2, "segments": [
                      {"positions": (N, 6), "velocities": (N, 6), "marks": [(sample, label)]},
                      ...]}   played in order; a mark reports its label when its sample is passed
                   {"op": "stop"}  {"op": "resume"}  {"op": "abort"}
  cycle -> server  {"op": "feedback", "time": s, "position": [rad], "velocity": [rad/s],
                    "command": [rad], "enable": EnableState, "estop": bool}
                   {"op": "mark", "id", "label"}  {"op": "paused", "id"}  {"op": "resumed", "id"}
                   {"op": "done", "id"}  {"op": "failed", "id", "message"}  {"op": "aborted", "id"}
"""
from __future__ import annotations

import numpy as np

from landscape.sim.controller import Controller, EnableState, EstopState, JointCmd

# At rest means: every joint this close to its command (rad) and this slow (rad/s); an arm that
# is not there after SETTLE_TIMEOUT (s) is reported anyway, with its following error.
SETTLE_POSITION = 1e-5
SETTLE_VELOCITY = 1e-3
SETTLE_TIMEOUT = 1.0


class _Motion:
    """A run: trajectory segments played back to back (each starts where the last one ended)."""

    def __init__(self, msg: dict, dt: float):
        self.id = msg["id"]
        self.dt = dt
        self.segments = list(msg["segments"])
        self._load(0)
        self.limit = np.asarray(msg["acceleration"], dtype=float)   # rad/s^2, per joint
        self.rate = 1.0         # samples per cycle
        self.target_rate = 1.0  # 0 while stopping, 1 while running or resuming
        self.paused = False
        self.abort_when_paused = False
        self.settling: str | None = None   # what to report once the arm has settled
        self.settle_cycles = 0

    def _load(self, index: int) -> None:
        if index == 0 or self.before is None:
            self.join_step = np.zeros(6)   # rad: the last step before this segment's start
        else:   # the segment before ended where this one starts: remember its last step
            self.join_step = self.positions[-1] - self._position_at(self.before)
        self.before: float | None = None   # s before the last advance, in this segment
        self.segment = index
        segment = self.segments[index]
        self.positions = np.asarray(segment["positions"], dtype=float)
        self.velocities = np.asarray(segment["velocities"], dtype=float)
        # Sample-to-sample changes of position (rad) and velocity (rad/s), two rows of zeros past
        # the end (the play stops there): the slopes of the piecewise-linear play.
        n = len(self.positions)
        self._dp = np.zeros((n + 1, 6))
        self._dv = np.zeros((n + 1, 6))
        self._dp[:n - 1] = np.diff(self.positions, axis=0)
        self._dv[:n - 1] = np.diff(self.velocities, axis=0)
        self.marks = list(segment.get("marks", ()))
        self.s = 0.0

    def next_segment(self) -> bool:
        """At the end of a segment: go on with the next one, if any."""
        if self.segment + 1 >= len(self.segments):
            return False
        self._load(self.segment + 1)
        return True

    @property
    def last(self) -> int:
        return len(self.positions) - 1

    def sample(self, table: np.ndarray) -> np.ndarray:
        i = min(int(self.s), self.last)
        frac = self.s - i
        if frac == 0.0 or i == self.last:
            return table[i]
        return table[i] + frac * (table[i + 1] - table[i])

    def _position_at(self, s: float) -> np.ndarray:
        i = min(int(s), self.last)
        return self.positions[i] + (s - i) * self._dp[i]

    @property
    def ramping(self) -> bool:
        return self.rate != self.target_rate

    def advance(self) -> None:
        if self.ramping:
            self.rate = self._next_rate()
        self.before = self.s
        self.s = min(self.s + self.rate, float(self.last))

    def _next_rate(self) -> float:
        """The rate for the next cycle, as near the target as keeping every joint's commanded
        acceleration within its limit allows: both the second difference of the commanded
        positions over dt^2 (what the drives follow) and the change of the commanded velocity
        over dt.

        The play is piecewise linear between samples: the next step p(s + x) - p(s) is linear
        in the next rate x on [0, 1 - frac] and on [1 - frac, 1], the next commanded velocity
        v(s + x) x quadratic. Keeping the rate qualifies (the trajectory keeps the limits at
        rate 1, and a piecewise-linear play at a rate r <= 1 averages its differences), and no
        bound changes side between r and the nearest root of any bound towards the target:
        that root (or the target, if nearer) is the next rate. So a stop or a restart never
        asks more of a joint than its limit.
        """
        r, target, s = self.rate, self.target_rate, self.s
        i = min(int(s), self.last)
        frac = s - i
        split = 1.0 - frac
        dp, dv, v = self._dp[i:i + 2], self._dv[i:i + 2], self.velocities
        here = v[i] + frac * dv[0]
        if self.before is None:
            step = self.join_step
        else:
            step = self.positions[i] + frac * dp[0] - self._position_at(self.before)
        # Per piece (axis 0: before and after the next sample): step(x) = p0 + dp x,
        # velocity(x) = x (w0 + dv x); bounds on both sides (axis 0 of `sides`).
        p0 = np.array([np.zeros(6), (dp[0] - dp[1]) * split])
        w0 = np.array([here, v[min(i + 1, self.last)] - dv[1] * split])
        sides = np.array([[[-1.0]], [[1.0]]])
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            linear = (step + sides * (self.limit * self.dt * self.dt) - p0) / dp
            c = here * r + sides * (self.limit * self.dt)          # dv x^2 + w0 x - c = 0
            q = -0.5 * (w0 + np.copysign(np.sqrt(w0 * w0 + 4.0 * dv * c), w0))
            quadratic = np.stack([q / dv, -c / q])   # -c / q is also the root when dv = 0
            roots = np.concatenate([linear[None], quadratic])     # (3, 2 sides, 2 pieces, 6)
            # How each bound's margin changes with x at its root: a bound is left, going
            # towards the target, where the margin shrinks that way.
            slope = sides * np.concatenate([np.broadcast_to(dp, linear.shape)[None],
                                            w0 + 2.0 * dv * quadratic])
        # The first root towards the target, within its own piece, where a bound is left.
        inside = (roots >= [[0.0], [split]]) & (roots <= [[split], [1.0]])
        if target < r:
            valid = inside & (roots >= target) & (roots <= r) & (slope < 0.0)
            return float(np.max(roots, where=valid, initial=target))
        valid = inside & (roots >= r) & (roots <= target) & (slope > 0.0)
        return float(np.min(roots, where=valid, initial=target))


class Executor:
    def __init__(self, mailbox, cycle_time: float, feedback_every: int = 5):
        self.mailbox = mailbox
        self.cycle_time = cycle_time
        self.feedback_every = feedback_every
        self._hold: np.ndarray | None = None   # commanded position when not moving, rad
        self._motion: _Motion | None = None
        self._cycles = 0
        self._last_state = None
        self._reports: list[dict] = []   # motion reports of this cycle, posted after feedback

    def __call__(self, ctrl: Controller) -> bool:
        fbk = ctrl.get()
        state = ctrl.state()
        enabled = state.enable is EnableState.ENABLED
        while (msg := self.mailbox.poll()) is not None:
            self._handle(msg)
        if not enabled or self._hold is None:
            self._hold = fbk.pos.copy()
            if self._motion is not None and not enabled:
                self._end("failed", message="drives disabled during the motion")
        if self._motion is not None:
            pos, vel = self._play(self._motion, fbk)
        else:
            pos, vel = self._hold, np.zeros_like(self._hold)
        ctrl.set(JointCmd(pos, vel))

        self._cycles += 1
        key = (state.enable, state.estop)
        # Feedback goes first, so the server sees where the arm is when a report arrives.
        if key != self._last_state or self._cycles % self.feedback_every == 0 or self._reports:
            self._last_state = key
            self.mailbox.post({
                "op": "feedback", "time": getattr(ctrl, "time", 0.0),
                "position": fbk.pos.tolist(), "velocity": fbk.vel.tolist(),
                "command": pos.tolist(), "enable": state.enable,
                "estop": state.estop is EstopState.ESTOP})
        for report in self._reports:
            self.mailbox.post(report)
        self._reports.clear()
        return True

    def _play(self, motion: _Motion, fbk) -> tuple[np.ndarray, np.ndarray]:
        if motion.settling is None:
            motion.advance()
            while motion.marks and motion.marks[0][0] <= motion.s:
                self._reports.append({"op": "mark", "id": motion.id,
                                      "label": motion.marks.pop(0)[1]})
            if motion.s >= motion.last and not motion.next_segment():
                motion.settling = "done"
            elif motion.target_rate == 0.0 and motion.rate == 0.0 and not motion.paused:
                motion.settling = "aborted" if motion.abort_when_paused else "paused"
            else:
                self._hold = motion.sample(motion.positions)
                return self._hold, motion.sample(motion.velocities) * motion.rate
            self._hold = motion.sample(motion.positions)
        # At the end of the motion or of a stop ramp: hold until the arm has settled there, so
        # "done" and "paused" mean the arm is at rest where the command says.
        motion.settle_cycles += 1
        error = float(np.max(np.abs(fbk.pos - self._hold)))
        settled = error < SETTLE_POSITION and float(np.max(np.abs(fbk.vel))) < SETTLE_VELOCITY
        if settled or motion.settle_cycles * self.cycle_time > SETTLE_TIMEOUT:
            note = {} if settled else {"message": f"not settled within {SETTLE_TIMEOUT:g} s "
                                                  f"(following error {error:.2e} rad)"}
            if motion.settling == "paused":
                motion.paused, motion.settling, motion.settle_cycles = True, None, 0
                self._reports.append({"op": "paused", "id": motion.id, **note})
            else:
                self._end(motion.settling, **note)
        return self._hold, np.zeros_like(self._hold)

    def _handle(self, msg: dict) -> None:
        op, motion = msg.get("op"), self._motion
        if op == "run":
            if motion is not None:
                self._end("aborted")
            self._motion = _Motion(msg, self.cycle_time)
        elif op == "stop" and motion is not None and not motion.paused and motion.settling is None:
            motion.target_rate = 0.0
        elif op == "resume" and motion is not None and motion.paused:
            motion.paused = False
            motion.target_rate = 1.0
            self._reports.append({"op": "resumed", "id": motion.id})
        elif op == "abort" and motion is not None:
            if motion.paused:
                self._end("aborted")
            elif motion.settling is None:  # never drop a moving arm: stop along the path first
                motion.abort_when_paused = True
                motion.target_rate = 0.0

    def _end(self, how: str, **details) -> None:
        self._reports.append({"op": how, "id": self._motion.id, **details})
        self._motion = None
