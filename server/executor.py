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

Every cycle's feedback goes into the feedback ring (feedback.py). Messages, plain dicts
(picklable, so they cross the process boundary):
  server -> cycle  {"op": "run", "id": str, "acceleration": (6,) rad/s^2 (ramps that start and
                    resume), "stop_acceleration": (6,) rad/s^2 (stops: the arm's own),
                    "arrays": SharedArrays of `pack_run`}: segments played in order; a mark
                    reports its label when its sample is passed
                   {"op": "stop"}  {"op": "resume"}  {"op": "abort"}
  cycle -> server  {"op": "controller", "enable": EnableState value, "estop": bool} on change
                   {"op": "started", "id", "wall_time"}  {"op": "mark", "id", "label",
                    "wall_time"} (wall_time: unix s of the cycle)
                   {"op": "paused", "id"}  {"op": "resumed", "id"}  {"op": "done", "id"}
                   {"op": "failed", "id", "message"}  {"op": "aborted", "id"}
"""
from __future__ import annotations

import time

import numpy as np

from landscape.server.feedback import (CMD, ENABLE, ESTOP, QD, SEQ, TAU, TIME, WALL, WIDTH, Q,
                                       FeedbackRing)
from landscape.sim.controller import Controller, EnableState, EstopState, JointCmd
from landscape.sim.shared_array import SharedArrays

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

    def _load(self, index: int) -> None:
        self.segment = index
        segment = self.segments[index]
        self.positions = np.asarray(segment["positions"], dtype=float)
        self.velocities = np.asarray(segment["velocities"], dtype=float)
        # The trajectory's acceleration at rate 1, sample i to i + 1 (rad/s^2): precomputed by
        # the server for a run, so that loading a long segment costs the cycle nothing.
        self.accelerations = segment.get("accelerations")
        if self.accelerations is None:
            self.accelerations = np.diff(self.velocities, axis=0,
                                         append=self.velocities[-1:]) / self.dt
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

    @property
    def ramping(self) -> bool:
        return self.rate != self.target_rate

    def advance(self) -> None:
        if self.ramping:
            self.rate = self._next_rate()
        self.s = min(self.s + self.rate, float(self.last))

    def _next_rate(self) -> float:
        """The rate one cycle on, moving towards the target as fast as the limits allow.

        Joint j's commanded velocity goes from v r to about v r' + a dt r'^2 (the path's own
        change over the r' samples played), so its acceleration is A r'^2 + B (r' - r) with
        B = |v| / dt and A = a sign(v); the next rate is the root of that equal to -limit
        (stopping) or +limit (resuming), taken over the joints that bind.
        """
        i = min(int(self.s), self.last)
        v, r = self.sample(self.velocities), self.rate
        moving = np.abs(v) > 1e-9
        if not np.any(moving):   # nothing moves here: the rate can jump
            return self.target_rate
        stopping = self.target_rate < r
        b = np.abs(v[moving]) / self.dt
        # The step may cross into the next sample interval: take the less favourable of the two.
        signed = self.accelerations[i:i + 2, moving] * np.sign(v[moving])
        a = signed.min(axis=0) if stopping else signed.max(axis=0)
        c = b * r + (-self.limit[moving] if stopping else self.limit[moving])
        # Root of a x^2 + b x - c = 0 in the form that stays exact as a goes to 0.
        roots = 2 * c / (b + np.sqrt(np.maximum(b * b + 4 * a * c, 0.0)))
        if stopping:
            return min(max(float(np.max(roots)), self.target_rate), r)
        return max(min(float(np.min(roots)), self.target_rate), r)


class Executor:
    """The cyclic function. `ring` receives every cycle's feedback (feedback.py); reports go to
    the server through `mailbox`, in order, after that cycle's row."""

    def __init__(self, mailbox, cycle_time: float, ring: FeedbackRing | None = None):
        self.mailbox = mailbox
        self.cycle_time = cycle_time
        self.ring = ring
        self._sequence = ring.head + 1 if ring is not None else 0   # goes on after a restart
        self._row = np.full(WIDTH, np.nan)
        self._hold: np.ndarray | None = None   # commanded position when not moving, rad
        self._motion: _Motion | None = None
        self._arrays: SharedArrays | None = None   # the running motion's trajectory block
        self._last_state = None
        self._reports: list[dict] = []   # reports of this cycle, posted after its row

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
        self.ring.write(self._sequence, row)
        self._sequence += 1

    def _play(self, motion: _Motion, fbk) -> tuple[np.ndarray, np.ndarray]:
        if motion.settling is None:
            motion.advance()
            marks = motion.marks
            while motion.next_mark < len(marks) and marks[motion.next_mark][0] <= motion.s:
                self._reports.append({"op": "mark", "id": motion.id, "wall_time": time.time(),
                                      "label": int(marks[motion.next_mark][1])})
                motion.next_mark += 1
            if motion.s >= motion.last and not motion.next_segment():
                motion.settling = "done"
            elif motion.target_rate == 0.0 and motion.rate == 0.0 and not motion.paused:
                motion.settling = "aborted" if motion.abort_when_paused else "paused"
            else:
                self._hold = motion.sample(motion.positions).copy()   # outlives the motion's arrays
                return self._hold, motion.sample(motion.velocities) * motion.rate
            self._hold = motion.sample(motion.positions).copy()   # outlives the motion's arrays
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
            self._arrays = msg["arrays"]
            self._motion = _Motion({**msg, "segments": _Segments(self._arrays.open())},
                                   self.cycle_time)
            self._motion.stop_limit = np.asarray(msg["stop_acceleration"], dtype=float)
            self._reports.append({"op": "started", "id": msg["id"], "wall_time": time.time()})
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

    def _end(self, how: str, **details) -> None:
        self._reports.append({"op": how, "id": self._motion.id, **details})
        self._motion = None
        if self._arrays is not None:
            self._arrays.close()
            self._arrays = None


class _Segments:
    """The segments of a run, read from its shared arrays when played (not all at once: a run
    may have many): "positions", "velocities", "accelerations" (N, 6), "marks" (M, 2) as
    (sample in its segment, label), and "segments" (S, 4): row start, row end, first mark,
    end of marks."""

    def __init__(self, arrays: dict):
        self._a = arrays

    def __len__(self) -> int:
        return len(self._a["segments"])

    def __getitem__(self, index: int) -> dict:
        start, end, m0, m1 = (int(v) for v in self._a["segments"][index])
        return {"positions": self._a["positions"][start:end],
                "velocities": self._a["velocities"][start:end],
                "accelerations": self._a["accelerations"][start:end],
                "marks": self._a["marks"][m0:m1]}


def pack_run(trajectories, dt: float) -> dict[str, np.ndarray]:
    """The arrays of a run of back-to-back trajectories, for `_Segments` (server side)."""
    rows = [0]
    marks, segments = [], []
    for t in trajectories:
        m0 = len(marks)
        marks.extend(t.marks)
        segments.append((rows[-1], rows[-1] + len(t), m0, len(marks)))
        rows.append(rows[-1] + len(t))
    positions = np.concatenate([t.positions for t in trajectories])
    velocities = np.concatenate([t.velocities for t in trajectories])
    accelerations = np.concatenate([
        np.diff(t.velocities, axis=0, append=t.velocities[-1:]) / dt for t in trajectories])
    return {"positions": positions, "velocities": velocities, "accelerations": accelerations,
            "marks": np.array(marks, dtype=np.int64).reshape(-1, 2),
            "segments": np.array(segments, dtype=np.int64).reshape(-1, 4)}
