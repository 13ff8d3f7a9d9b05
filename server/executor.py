"""The device server's cyclic function: the per-cycle part of the device, in the cycle process.

Every cycle (LLI 5.3.10) it reads the feedback, takes the server's messages, computes the
setpoint and sets it. While the drives are not enabled it commands the measured position, so
that enabling starts from where the arm is and never jumps (LLI 5.3.3).

A motion is a timed trajectory sampled at the cycle time (motion/trajectory.py), played one
sample per cycle. Stopping and resuming scale time, not space: a play rate r in [0, 1] advances
the sample index by r per cycle, so the arm slows down and speeds up along the planned path and
never leaves it (seed 3.6). Played at rate r, joint j moves at v_j r and accelerates at
a_j r^2 + v_j dr/dt (v, a: the trajectory's at rate 1); each cycle the rate changes as fast as
keeping every joint's acceleration within its limit allows, measured as the drives see it: the
second difference of the commanded positions (played piecewise linearly between samples) and
the change of the commanded velocity (_Motion._next_rate). Keeping the rate always qualifies
(the trajectory is within the limits at r = 1, so at any r <= 1), so a stop or a restart never
asks more of a joint than its limit.

A motion may carry a sensor loop (force_control.py): a guard (moveReact) that stops it when a
sensor crosses a threshold, a compliance (comply) that shifts its setpoints to hold a force.
Instead of a motion, a jog session (jog_control.py) may integrate velocity requests. Sensors,
the I/O image and the I/O watches are read every cycle (cycle_inputs.py), so the loops see
this cycle's readings.

Every cycle's feedback goes into the feedback ring (feedback.py). Messages, plain dicts
(picklable, so they cross the process boundary):
  server -> cycle  {"op": "run", "id": str, "acceleration": (6,) rad/s^2 (ramps that start and
                    resume), "stop_acceleration": (6,) rad/s^2 (stops: the arm's own),
                    "arrays": SharedArrays of run_arrays.pack_run, optional "guard": GuardSpec,
                    "comply": ComplySpec}: segments played in order; a mark reports its label
                    when its sample is passed
                   {"op": "comply", "id", "spec": ComplySpec}: compliance for the running motion
                   {"op": "stop"}  {"op": "resume"}  {"op": "abort"}
                   the jog messages (jog_control.py) and the I/O ones (cycle_inputs.py)
  cycle -> server  {"op": "controller", "enable": EnableState value, "estop": bool} on change
                   {"op": "started", "id", "wall_time"}  {"op": "mark", "id", "label",
                    "wall_time"} (wall_time: unix s of the cycle)
                   {"op": "paused", "id"}  {"op": "resumed", "id"}  {"op": "done", "id"}
                   {"op": "failed", "id", "message"}  {"op": "aborted", "id"}
                   a guarded motion's end adds "guard": {"event": "triggered" | "envelope" |
                   "full distance", "values": (3,), "position": (6,) rad}; a compliant one's
                   "comply": {"offset": (3,) m, "force": (3,) N, "panic": code or None}
"""
from __future__ import annotations

import time

import numpy as np

from landscape.server.cycle_inputs import CycleSensors, IoMonitor
from landscape.server.feedback import (CMD, ENABLE, ESTOP, IO, QD, SENSORS, SEQ, TAU, TIME, WALL,
                                       WIDTH, Q, FeedbackRing)
from landscape.server.force_control import RANGE_KIND, Admittance, ThresholdMonitor, vector
from landscape.server.jog_control import JogIntegrator
from landscape.server.run_arrays import Segments
from landscape.sim.arm import ArmModel
from landscape.sim.controller import Controller, EnableState, EstopState, JointCmd
from landscape.sim.shared_array import SharedArrays

# At rest means: every joint this close to its command (rad) and this slow (rad/s); an arm that
# is not there after SETTLE_TIMEOUT (s) is reported anyway, with its following error. An arm in
# contact (a motion with a sensor loop) rests where the contact lets it: SETTLE_CONTACT (rad).
SETTLE_POSITION = 1e-5
SETTLE_CONTACT = 1e-3
SETTLE_VELOCITY = 1e-3
SETTLE_TIMEOUT = 1.0


class _Motion:
    """A run: trajectory segments played back to back (each starts where the last one ended)."""

    def __init__(self, msg: dict, dt: float):
        self.id = msg["id"]
        self.dt = dt
        self.segments = msg["segments"]   # a sequence; read one segment at a time
        self._load(0)
        # rad/s^2 per joint: the ramps' limit, `run_limit` to start and resume; a stop sets
        # `stop_limit` (the arm's own, by default the same).
        self.limit = self.run_limit = self.stop_limit = np.asarray(msg["acceleration"], dtype=float)
        self.rate = 1.0         # samples per cycle
        self.target_rate = 1.0  # 0 while stopping, 1 while running or resuming
        self.paused = False
        self.abort_when_paused = False
        self.settling: str | None = None   # what to report once the arm has settled
        self.settle_cycles = 0
        self.end_as: str | None = None     # a sensor loop's stop: how the motion ends
        self.outcome: dict = {}            # what the loops add to the final report
        self.guard: ThresholdMonitor | None = None
        self.compliance: Admittance | None = None

    def _load(self, index: int) -> None:
        if index == 0 or self.before is None:
            self.join_step = np.zeros(6)   # rad: the last step before this segment's start
        else:   # the segment before ended where this one starts: remember its last step
            self.join_step = self.positions[-1] - self._position_at(self.before)
        self.before: float | None = None   # s before the last advance, in this segment
        self.segment = index
        segment = self.segments[index]
        # Nothing here walks the whole segment: a long one costs the cycle nothing to load.
        self.positions = np.asarray(segment["positions"], dtype=float)
        self.velocities = np.asarray(segment["velocities"], dtype=float)
        self.marks = segment.get("marks", ())   # (sample, label) rows, in order
        self.next_mark = 0
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
        return self.positions[i] + (s - i) * (self.positions[min(i + 1, self.last)]
                                              - self.positions[i])

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
        r, target, s, n = self.rate, self.target_rate, self.s, self.last
        i = min(int(s), n)
        frac = s - i
        split = 1.0 - frac
        # The changes over the two sample intervals ahead (none past the end: the play stops).
        rows = [i, min(i + 1, n), min(i + 2, n)]
        P, V = self.positions[rows], self.velocities[rows]            # (3, 6)
        dp, dv = P[1:] - P[:-1], V[1:] - V[:-1]                       # (2, 6)
        here = V[0] + frac * dv[0]
        if self.before is None:
            step = self.join_step
        else:
            step = P[0] + frac * dp[0] - self._position_at(self.before)
        # Per piece (axis 0: before and after the next sample): step(x) = p0 + dp x,
        # velocity(x) = x (w0 + dv x); each bound on both sides (axis 0 of _SIDES).
        p0 = dp * _PIECE_START
        p0[1] = (dp[0] - dp[1]) * split
        w0 = np.array([here, V[1] - dv[1] * split])
        with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
            linear = (step + _SIDES * (self.limit * (self.dt * self.dt)) - p0) / dp
            c = here * r + _SIDES * (self.limit * self.dt)           # dv x^2 + w0 x - c = 0
            q = -0.5 * (w0 + np.copysign(np.sqrt(w0 * w0 + 4.0 * dv * c), w0))
            first, second = q / dv, -c / q    # -c / q is also the root when dv = 0
            # How each bound's margin changes with x at its root: a bound is left, going
            # towards the target, where the margin shrinks that way.
            roots = np.stack([linear, first, second])             # (3, 2 sides, 2 pieces, 6)
            slope = _SIDES * np.stack([np.broadcast_to(dp, linear.shape),
                                       w0 + 2.0 * dv * first, w0 + 2.0 * dv * second])
        # The first root towards the target, within its own piece, where a bound is left.
        if target < r:
            valid = (slope < 0.0) & (roots >= max(target, 0.0)) & (roots <= min(r, 1.0))
        else:
            valid = (slope > 0.0) & (roots >= r) & (roots <= target)
        valid &= (roots >= [[0.0], [split]]) & (roots <= [[split], [1.0]])
        if target < r:
            return float(np.max(roots, where=valid, initial=target))
        return float(np.min(roots, where=valid, initial=target))


_SIDES = np.array([[[-1.0]], [[1.0]]])          # a bound's two sides, -limit and +limit
_PIECE_START = np.zeros((2, 1))                 # p0 of the first piece: the step starts at 0


class Executor:
    """The cyclic function. `ring` receives every cycle's feedback (feedback.py); reports go to
    the server through `mailbox`, in order, after that cycle's row. `arm`: the arm model for
    the loops that need its Jacobian (jog, comply); without it they are refused."""

    def __init__(self, mailbox, cycle_time: float, ring: FeedbackRing | None = None,
                 arm: ArmModel | None = None):
        self.mailbox = mailbox
        self.cycle_time = cycle_time
        self.ring = ring
        self._sequence = ring.head + 1 if ring is not None else 0   # goes on after a restart
        self._row = np.full(WIDTH, np.nan)
        self._hold: np.ndarray | None = None   # commanded position when not moving, rad
        self._motion: _Motion | None = None
        self._jog: JogIntegrator | None = None
        self._arrays: SharedArrays | None = None   # the running motion's trajectory block
        self._last_state = None
        self._reports: list[dict] = []   # reports of this cycle, posted after its row
        self._last_setpoint: np.ndarray | None = None   # a compliant motion's, last cycle
        self._sensors = CycleSensors()
        self._io = IoMonitor()
        self._tip = None
        if arm is not None:
            from landscape.server.tip_model import TipModel   # pinocchio: only where it runs
            self._tip = TipModel(arm)

    @property
    def sequence(self) -> int:
        """The sequence number the next cycle's row gets."""
        return self._sequence

    def __call__(self, ctrl: Controller) -> bool:
        fbk = ctrl.get()
        state = ctrl.state()
        enabled = state.enable is EnableState.ENABLED
        while (msg := self.mailbox.poll()) is not None:
            self._handle(msg, fbk)
        sensors = self._sensors.read(ctrl, self._sequence)
        self._io.poll(ctrl, self._sequence, self._reports)
        if not enabled or self._hold is None:
            self._hold = fbk.pos.copy()
            if self._motion is not None and not enabled:
                self._end("failed", message="drives disabled during the motion")
            if self._jog is not None and not enabled:
                self._end_jog("failed", "drives disabled while jogging")
        if self._motion is not None:
            pos, vel = self._play(self._motion, fbk, sensors)
        elif self._jog is not None:
            pos, vel = self._jog.step()
            self._hold = pos.copy()
            if self._jog.finished:
                self._end_jog(*self._jog.ending)
        else:
            pos, vel = self._hold, np.zeros_like(self._hold)
        ctrl.set(JointCmd(pos, vel))

        key = (state.enable, state.estop)
        if key != self._last_state:   # first, so the server knows the power before the rest
            self._last_state = key
            self._reports.insert(0, {"op": "controller", "enable": int(state.enable),
                                     "estop": state.estop is EstopState.ESTOP})
        if self.ring is not None:
            self._write_row(ctrl, fbk, pos, state)
        for report in self._reports:
            self.mailbox.post(report)
        self._reports.clear()
        return True

    def _write_row(self, ctrl, fbk, pos, state) -> None:
        row = self._row
        row[SEQ] = self._sequence
        row[TIME] = getattr(ctrl, "time", 0.0)
        row[WALL] = time.time()
        row[Q], row[QD], row[CMD], row[TAU] = fbk.pos, fbk.vel, pos, fbk.torque
        row[ENABLE] = int(state.enable)
        row[ESTOP] = 1.0 if state.estop is EstopState.ESTOP else 0.0
        row[SENSORS] = self._sensors.values
        row[IO] = self._io.image
        self.ring.write(self._sequence, row)
        self._sequence += 1

    def _play(self, motion: _Motion, fbk, sensors) -> tuple[np.ndarray, np.ndarray]:
        if motion.settling is None:
            motion.advance()
            marks = motion.marks
            while motion.next_mark < len(marks) and marks[motion.next_mark][0] <= motion.s:
                self._reports.append({"op": "mark", "id": motion.id, "wall_time": time.time(),
                                      "label": int(marks[motion.next_mark][1])})
                motion.next_mark += 1
            running = motion.target_rate == 1.0 and not motion.paused
            if running:
                self._watch(motion, fbk, sensors)
            if motion.s >= motion.last and not motion.next_segment():
                if not (motion.compliance is not None and motion.compliance.holding):
                    motion.settling = motion.end_as or "done"
            elif motion.target_rate == 0.0 and motion.rate == 0.0 and not motion.paused:
                motion.settling = motion.end_as or ("aborted" if motion.abort_when_paused
                                                    else "paused")
            if motion.settling is None:
                # outlives the motion's arrays
                self._hold = self._shifted(motion, sensors, running and motion.settling is None)
                velocity = motion.sample(motion.velocities) * motion.rate
                if motion.compliance is not None:
                    velocity = velocity + (self._hold - self._last_setpoint) / self.cycle_time
                self._last_setpoint = self._hold
                return self._hold, velocity
            self._hold = self._shifted(motion, sensors, False)
        # At the end of the motion or of a stop ramp: hold until the arm has settled there, so
        # "done" and "paused" mean the arm is at rest where the command says.
        motion.settle_cycles += 1
        error = float(np.max(np.abs(fbk.pos - self._hold)))
        in_contact = motion.compliance is not None or "guard" in motion.outcome
        tolerance = SETTLE_CONTACT if in_contact else SETTLE_POSITION
        settled = error < tolerance and float(np.max(np.abs(fbk.vel))) < SETTLE_VELOCITY
        if settled or motion.settle_cycles * self.cycle_time > SETTLE_TIMEOUT:
            note = {} if settled else {"message": f"not settled within {SETTLE_TIMEOUT:g} s "
                                                  f"(following error {error:.2e} rad)"}
            if motion.settling == "paused":
                motion.paused, motion.settling, motion.settle_cycles = True, None, 0
                self._reports.append({"op": "paused", "id": motion.id, **note})
            else:
                if "message" in motion.outcome and "message" in note:
                    note["message"] = f"{motion.outcome['message']}; {note['message']}"
                if motion.compliance is not None:
                    motion.outcome["comply"] = motion.compliance.summary(sensors)
                self._end(motion.settling, **{**motion.outcome, **note})
        return self._hold, np.zeros_like(self._hold)

    # ---- sensor loops ----------------------------------------------------------------------

    def _watch(self, motion: _Motion, fbk, sensors) -> None:
        """A running motion's sensor loops: a guard that fires, or a compliance that must stop,
        brake the motion at the arm's full deceleration."""
        if motion.guard is not None:
            verdict = motion.guard.check(sensors)
            if verdict is not None:
                event, values = verdict
                motion.guard = None
                self._sensors.watch_range = False
                motion.outcome["guard"] = {"event": event, "values": values.tolist(),
                                           "position": fbk.pos.tolist()}
                if event == "envelope":
                    motion.outcome["message"] = (f"sensor reading {vector(values)} left its "
                                                 f"envelope")
                _brake(motion, "done" if event == "triggered" else "failed")
        compliance = motion.compliance
        if compliance is not None and compliance.problem is not None and motion.end_as is None:
            motion.outcome["message"] = compliance.problem
            _brake(motion, "failed")

    def _shifted(self, motion: _Motion, sensors, active: bool) -> np.ndarray:
        """The motion's setpoint now: planned, shifted by its compliance if it has one."""
        planned = motion.sample(motion.positions)
        compliance = motion.compliance
        if compliance is None:
            return planned.copy()
        return compliance.shift(planned, sensors, active)

    def _attach(self, motion: _Motion, msg: dict) -> None:
        """The run's sensor loops (a missing arm model refuses a compliance)."""
        guard, comply = msg.get("guard"), msg.get("comply")
        if guard is not None:
            motion.guard = ThresholdMonitor(guard)
            self._sensors.watch_range = guard.kind == RANGE_KIND
            motion.outcome["guard"] = {"event": "full distance"}
        if comply is not None:
            motion.compliance = Admittance(comply, self._tip, self.cycle_time)
            self._last_setpoint = motion.sample(motion.positions).copy()

    # ---- messages ----------------------------------------------------------------------------

    def _handle(self, msg: dict, fbk) -> None:
        op, motion = msg.get("op"), self._motion
        if op in ("io_image", "watch", "unwatch"):
            self._io.handle(msg)
        elif op in ("jog", "jog_velocity", "jog_end"):
            self._handle_jog(msg, fbk)
        elif op == "run":
            if motion is not None:
                self._end("aborted")
            self._arrays = msg["arrays"]
            self._motion = _Motion({**msg, "segments": Segments(self._arrays.open())},
                                   self.cycle_time)
            self._motion.stop_limit = np.asarray(msg["stop_acceleration"], dtype=float)
            self._reports.append({"op": "started", "id": msg["id"], "wall_time": time.time()})
            if msg.get("comply") is not None and self._tip is None:
                self._end("failed", message="this controller has no arm model for comply")
            else:
                self._attach(self._motion, msg)
        elif op == "comply" and motion is not None and motion.id == msg["id"]:
            if motion.compliance is None and self._tip is not None:
                self._attach(motion, {"comply": msg["spec"]})
        elif self._jog is not None and op in ("stop", "abort"):
            self._jog.end("aborted", f"{op} while jogging")
        elif op == "stop" and motion is not None and not motion.paused and motion.settling is None:
            motion.limit = motion.stop_limit   # stops brake at the arm's full deceleration
            motion.target_rate = 0.0
        elif op == "resume" and motion is not None and motion.paused:
            motion.limit = motion.run_limit
            motion.paused = False
            motion.target_rate = 1.0
            self._reports.append({"op": "resumed", "id": motion.id})
        elif op == "abort" and motion is not None:
            if motion.paused:
                self._end("aborted")
            elif motion.settling is None:  # never drop a moving arm: stop along the path first
                motion.limit = motion.stop_limit
                motion.abort_when_paused = True
                motion.target_rate = 0.0

    def _handle_jog(self, msg: dict, fbk) -> None:
        op, jog = msg["op"], self._jog
        if op == "jog":
            self._reports.append({"op": "started", "id": msg["id"], "wall_time": time.time()})
            if self._motion is not None or jog is not None or self._tip is None:
                why = ("this controller has no arm model for jogging" if self._tip is None
                       else "the arm is moving")
                self._reports.append({"op": "failed", "id": msg["id"], "message": why})
                return
            start = self._hold if self._hold is not None else fbk.pos
            self._jog = JogIntegrator(msg["id"], start, msg["limits"], self._tip,
                                      np.asarray(msg["tool_offset"], dtype=float),
                                      self.cycle_time)
        elif jog is not None and op == "jog_velocity":
            jog.command(msg)
        elif jog is not None and op == "jog_end":
            jog.end("done")

    def _end_jog(self, how: str, message: str = "") -> None:
        self._reports.append({"op": how, "id": self._jog.id,
                              **({"message": message} if message else {})})
        self._jog = None

    def _end(self, how: str, **details) -> None:
        self._reports.append({"op": how, "id": self._motion.id, **details})
        self._motion = None
        self._sensors.watch_range = False
        if self._arrays is not None:
            self._arrays.close()
            self._arrays = None


def _brake(motion: _Motion, end_as: str) -> None:
    """Stop the motion at the arm's full deceleration; once at rest it ends as `end_as`."""
    motion.limit = motion.stop_limit
    motion.target_rate = 0.0
    motion.end_as = end_as
