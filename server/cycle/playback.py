"""Playing a run of timed trajectories in the cycle (executor.py): where the arm should be
each cycle, and how stops and restarts change the pace along the planned path.

A motion is a timed trajectory sampled at the cycle time (motion/trajectory.py), played one
sample per cycle. Stopping and resuming scale time, not space: the play position sigma (in
samples) advances by the play rate r in [0, 1] per cycle, so the arm slows down and speeds up
along the planned path and never leaves it (seed 3.6). Between samples the path is the quintic
Hermite curve through them (their velocities and accelerations by central differences: C2, so
a fractional play position keeps the motion smooth).

A change of rate is a ramp (ramps.py): a jerk-limited profile of sigma planned by ruckig in
the path parameter, from the state the play is in (sigma, r, dr/dt) to the rate wanted (0: a
stop, at rest; 1: a resume, which lands on a whole sample at full rate so that the play goes on
with the planned samples exactly). Before a ramp is played, every position it commands is
checked against the joints' acceleration and jerk limits (the second and third differences of
the commanded positions, with the three cycles before it and those after it); a ramp that
would exceed them is planned again with lower bounds, and where none fits (the trajectory
itself at its jerk or acceleration limit just then) the play goes on as planned and tries again
next cycle. So a stop, a resume, an abort and a guard's braking never ask more of a joint than
its limits, and the ramps' limits are the stop's or the run's: `stop_limit`/`stop_jerk` (the
arm's full deceleration, or the set one: executor.py's "stop_acceleration") and
`run_limit`/`run_jerk` (the set acceleration).
"""
from __future__ import annotations

import math
from typing import TYPE_CHECKING

import numpy as np

from landscape.server.cycle.ramps import RampPlanner, hermite_at
from landscape.server.cycle.joined_rows import JoinedRows
from landscape.server.cycle.run_arrays import GrowingSegments, Segments

if TYPE_CHECKING:
    from landscape.server.cycle.force_loops import Admittance, ForceSettle, ThresholdMonitor


class Motion:
    """A run: trajectory segments played back to back (each starts where the last one ended,
    at rest)."""

    def __init__(self, msg: dict, dt: float):
        self.id = msg["id"]
        self.dt = dt
        self.segments = msg["segments"]   # a sequence; read one segment at a time
        self.first_row = 0                # the segment's first sample among the run's
        self._curve_at: tuple | None = None   # (segment, s) of _curve_here
        self._load(0)
        # rad/s^2 and rad/s^3 per joint: the ramps' limits, `run_*` to resume, `stop_*` to stop.
        self.run_limit = self.stop_limit = np.asarray(msg["acceleration"], dtype=float)
        jerk = msg.get("jerk")
        self.run_jerk = self.stop_jerk = (np.asarray(jerk, dtype=float) if jerk is not None
                                          else self.run_limit / 0.02)
        self.rate = 1.0         # samples per cycle
        self.rate_change = 0.0  # samples per cycle^2
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
        self.force_settle: ForceSettle | None = None      # after its stop (force_loops.py)
        self.unsettled = ""   # why the force is not settled after all (a stop or an abort)
        self._ramp: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None   # sigma, r, dr
        self._braking: tuple[np.ndarray, np.ndarray] | None = None   # this stop's limits
        self._step = 0
        self._planner = RampPlanner(dt)
        self._recent = (self.positions[0],) * 3   # the last 3 played, newest first (read-only)
        # A run checked against the cell as it plays (run_check.py): its rows checked so far
        # (None: all) and how many rows a stop may take; `awaiting` while braking or held for
        # the next stretch.
        self.checked: int | None = msg.get("checked")
        self.brake_rows = int(msg.get("brake", 0))
        self.awaiting = False
        # A run timed as it plays: the blocks of its later pieces ("append"), mapped until the
        # motion is dropped.
        self._blocks: list = []

    def _load(self, index: int) -> None:
        self.segment = index
        segment = self.segments[index]
        # Nothing here walks the whole segment: a long one costs the cycle nothing to load.
        # A joined one (GrowingSegments) is read across its parts, and grows in place.
        rows = segment["positions"]
        self.positions = rows if isinstance(rows, JoinedRows) else np.asarray(rows, dtype=float)
        self.marks = segment.get("marks", ())   # (sample, label) rows, in order
        self.next_mark = 0
        self._next_mark_at = self._mark_at(0)
        self.s = 0.0

    def _mark_at(self, index: int) -> float:
        """The sample of mark `index` of the segment (inf: no such mark)."""
        return float(self.marks[index][0]) if index < len(self.marks) else math.inf

    def passed_marks(self) -> list[int]:
        """The labels of the marks the play position has passed since last asked, in order."""
        if self.s < self._next_mark_at:   # each cycle: one comparison, no array read
            return []
        labels = []
        while self.s >= self._next_mark_at:
            labels.append(int(self.marks[self.next_mark][1]))
            self.next_mark += 1
            self._next_mark_at = self._mark_at(self.next_mark)
        return labels

    def next_segment(self) -> bool:
        """At the end of a segment: go on with the next one, if any; stopping, the play waits
        at the next one's start (the same place, at rest) rather than ending."""
        if self.segment + 1 >= len(self.segments):
            if self.checked is not None:   # more to come (keep_to_checked braked before it)
                self.rate, self.rate_change, self._ramp = 0.0, 0.0, None
                self.target_rate, self.awaiting = 0.0, True
                return True
            return False
        self.first_row += len(self.positions)
        self._load(self.segment + 1)
        # The last one ended at rest: this one starts as planned, or waits there.
        self.rate, self.rate_change, self._ramp = self.target_rate, 0.0, None
        return True

    @property
    def last(self) -> int:
        return len(self.positions) - 1

    def _curve(self) -> tuple[np.ndarray, np.ndarray]:
        """The Hermite curve and its slope at the play position, worked out once per position:
        a cycle asks for it three times (advance, the setpoint, its velocity). Read-only."""
        if self._curve_at != (self.segment, self.s):
            self._curve_at = (self.segment, self.s)
            self._curve_here = hermite_at(self.positions, self.s)
        return self._curve_here

    def position(self) -> np.ndarray:
        """The planned position at the play position (the Hermite curve between samples)."""
        return self._curve()[0]

    def velocity(self) -> np.ndarray:
        """The commanded velocity (rad/s): the Hermite curve's at the play position and rate
        (central differences at whole samples, so its change keeps the acceleration limit)."""
        return self._curve()[1] * (self.rate / self.dt)

    # ---- stops and resumes -------------------------------------------------------------------

    def stop(self, acceleration: np.ndarray | None = None, jerk: np.ndarray | None = None
             ) -> None:
        """Slow down to rest along the path (at the stop limits, or those given), then wait."""
        self.awaiting = False   # a stop asked for: paused (or ended) at rest, not resumed
        self.target_rate = 0.0
        self._braking = (self.stop_limit if acceleration is None else acceleration,
                         self.stop_jerk if jerk is None else jerk)

    def resume(self) -> None:
        """Speed up again along the path (at the run limits) to the planned pace."""
        self.paused = False
        self.target_rate = 1.0

    # ---- a run checked as it plays ----------------------------------------------------------

    def keep_to_checked(self) -> None:
        """Each cycle: brake along the path in time to rest before the rows not checked yet
        (the cycle never waits for them: it slows down), and go on once they are checked and
        the braking ramp is over (a resume planned in the middle of a stop ramp may not fit
        its bounds: ruckig refuses the input)."""
        if self.checked is not None and not self.awaiting and self.target_rate == 1.0:
            if self.first_row + self.s + self.brake_rows >= self.checked:
                self.awaiting = True
                self.target_rate = 0.0
                self._braking = (self.stop_limit, self.stop_jerk)
        elif self.awaiting and self._ramp is None and (
                self.checked is None or self.first_row + self.s + self.brake_rows < self.checked):
            self.awaiting = False
            self.target_rate = 1.0

    def checked_to(self, rows: int, everything: bool) -> None:
        """The rows up to `rows` are checked (`everything`: all of them): a play held for them
        goes on (keep_to_checked)."""
        self.checked = None if everything else rows

    def append(self, arrays, continues: bool, rows: int, brake: int, everything: bool) -> None:
        """Pieces timed and checked later (run_arrays.pack_run's arrays, shared): after the
        segments so far, the first joined to the last one if it `continues` it (the playing
        one included); `brake`: the rows a stop may take from the fastest of them all (the
        arm is never faster than the fastest it has); then as checked_to."""
        if not isinstance(self.segments, GrowingSegments):
            self.segments = GrowingSegments(self.segments)
        playing_last = self.segment == len(self.segments) - 1
        self._blocks.append(arrays)
        self.segments.append(Segments(arrays.open()), continues)
        if playing_last and continues:
            self._reload()
        self.brake_rows = brake
        self.checked_to(rows, everything)

    def _reload(self) -> None:
        """The playing segment read again (continued): the play goes on where it is."""
        s, next_mark = self.s, self.next_mark
        self._load(self.segment)
        self.s, self.next_mark, self._curve_at = s, next_mark, None
        self._next_mark_at = self._mark_at(next_mark)

    def refuse(self, message: str) -> bool:
        """A later stretch was refused: brake along the path, to fail with `message` at rest;
        True if the play is paused (at rest already: it fails now)."""
        self.outcome["message"] = message
        if not self.paused and self.settling is None:
            brake(self, "failed")
        return self.paused

    @property
    def ramping(self) -> bool:
        return self._ramp is not None or self.rate != self.target_rate

    def advance(self) -> None:
        """One cycle on: along a ramp, at the planned pace, or a ramp begun if one fits."""
        if self.target_rate == 1.0 and self.s == 0.0 and self._ramp is None:
            self.rate = 1.0     # a segment's start: at rest as planned, so play it as planned
        if self.rate != self.target_rate and (self._ramp is None
                                              or self._ramp[1][-1] != self.target_rate):
            self._plan_ramp()
        if self._ramp is not None:
            self._step += 1
            sigma, rate, change = self._ramp
            self.s, self.rate, self.rate_change = (float(sigma[self._step]),
                                                   float(rate[self._step]),
                                                   float(change[self._step]))
            if self._step == len(sigma) - 1:
                self._ramp = None
        elif self.rate == 1.0:
            self.s = min(self.s + 1.0, float(self.last))
        # Shifted by reference, not rolled: every cycle pays for this.
        self._recent = (self.position(), *self._recent[:2])

    def _plan_ramp(self) -> None:
        stopping = self.target_rate == 0.0
        acceleration, jerk = ((self._braking or (self.stop_limit, self.stop_jerk)) if stopping
                              else (self.run_limit, self.run_jerk))
        ramp = self._planner.plan(self.positions, np.array(self._recent), self.s, self.rate,
                                  self.rate_change, self.target_rate, acceleration, jerk)
        if ramp is not None:
            self._ramp, self._step = ramp, 0

    def note_peak(self, sensors) -> None:
        """A guard that fired: the reading furthest past its threshold since (each watched
        component, signed as read), for the final report ("peak")."""
        guard = self.stopped_by
        value = guard.reading(sensors)
        report = self.outcome["guard"]
        peak = np.array(report.get("peak", value), dtype=float)
        further = guard.watched & (np.sign(guard.thresholds) * (value - peak) > 0)
        peak[further] = value[further]
        report["peak"] = peak.tolist()


def brake(motion: Motion, end_as: str) -> None:
    """Stop the motion along its path at the stop limits; once at rest it ends as `end_as`."""
    motion.stop()
    motion.end_as = end_as
