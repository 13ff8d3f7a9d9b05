"""Playing a run of timed trajectories in the cycle (executor.py): where the arm should be
each cycle, and how fast the play rate may change.

A motion is a timed trajectory sampled at the cycle time (motion/trajectory.py), played one
sample per cycle. Stopping and resuming scale time, not space: a play rate r in [0, 1] advances
the sample index by r per cycle, so the arm slows down and speeds up along the planned path and
never leaves it (seed 3.6). Played at rate r, joint j moves at v_j r and accelerates at
a_j r^2 + v_j dr/dt (v, a: the trajectory's at rate 1); each cycle the rate changes as fast as
keeping every joint's acceleration within its limit allows, measured as the drives see it: the
second difference of the commanded positions (played piecewise linearly between samples) and
the change of the commanded velocity (Motion._next_rate). Keeping the rate always qualifies
(the trajectory is within the limits at r = 1, so at any r <= 1), so a stop or a restart never
asks more of a joint than its limit.
"""
from __future__ import annotations

from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from landscape.server.cycle.force_loops import Admittance, ForceSettle, ThresholdMonitor


class Motion:
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
        self.stopped_by: ThresholdMonitor | None = None   # the guard that fired
        self.force_settle: ForceSettle | None = None      # after its stop (force_control.py)
        self.unsettled = ""   # why the force is not settled after all (a stop or an abort)

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


def brake(motion: Motion, end_as: str) -> None:
    """Stop the motion at the arm's full deceleration; once at rest it ends as `end_as`."""
    motion.limit = motion.stop_limit
    motion.target_rate = 0.0
    motion.end_as = end_as
