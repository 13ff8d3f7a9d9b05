"""A long rest-to-rest section timed, sampled and checked stretch by stretch (issue 31 item 4):
time_path's jerk-limited timing with its raw TOPP-RA profile on a receding horizon
(horizon.py), so that the first rows can be played while the rest is timed.

time_path samples a section once it is timed whole, and slows it down uniformly where its
samples still exceed a limit. Here the filtered profile (window 2 T, jerk_timing.py: a long
section is a blended path with many turns) is sampled every dt as far as the raw pieces kept
so far make it final, and checked (sample_check.py). Where a sample exceeds a limit, the raw
stages behind it get lower limits (slowed_where_exceeded, time_path's local slow-down) and the
pieces from the last seam before them are timed again, round after round until the samples
hold. Rows are given out only up to a seam no such slow-down can reach any more (the
filter's window, three samples and LAG before the last sample checked), so a row once given
out never changes. No uniform slow-down: the last sample is the first whole cycle at or past
the end, at rest on the last waypoint.
"""
from __future__ import annotations

import math
from collections.abc import Iterator
from typing import NamedTuple

import numpy as np

from .horizon import RawStretch, joined, raw_in_stretches
from .jerk_timing import FilteredProfile, slowed_where_exceeded
from .sample_check import excess_per_sample
from .timing import LIMIT_SLACK, check_range, path_piece, section_problem
from .trajectory import Limits, PlanningError

__all__ = ["Chunk", "time_in_stretches", "LAG", "STRETCH", "HORIZON"]

LAG = 0.3          # s of checked rows held back (past the window): a slow-down's re-timing
                   # starts from a seam that far behind the excess, at a speed it can take
STRETCH = 0.5      # rad of path kept per raw piece
HORIZON = 2.0      # rad of path each piece is timed over (past the TX90's braking at full
                   # speed along a blended path: ~1.3 rad measured, test_horizon.py)
_MAX_ROUNDS = 12   # slow-downs of one stretch's samples before giving up with LIMITS


class Chunk(NamedTuple):
    """Rows of the section, given out in order: positions and velocities (k, 6), and marks
    (row in the section, waypoint index) of the waypoints they reach."""

    positions: np.ndarray
    velocities: np.ndarray
    marks: tuple[tuple[int, int], ...]


def time_in_stretches(waypoints, limits: Limits, dt: float, *, tool_path=None,
                      pass_speeds: dict[int, float] | None = None,
                      stretch: float = STRETCH, horizon: float = HORIZON) -> Iterator[Chunk]:
    """time_path(waypoints, limits, dt, ...) of ONE section (at rest at its ends only; limits
    with a jerk limit), as Chunks of rows, lazily: a chunk is given out as soon as the pieces
    timed so far make it final and checked. The rows together start and end at rest on the
    first and last waypoints, and keep every limit at every sample as time_path's do. Raises
    PlanningError as time_path (OUT_OF_JNT_RANGE, LIMITS), possibly after chunks were given
    out: the rows given out stay valid, and a caller brakes along them."""
    W = np.array(waypoints, dtype=float)
    if limits.jerk is None:
        raise ValueError("time_in_stretches needs limits with a jerk limit")
    index = np.arange(len(W))
    problem = section_problem(W, index, limits, dt, tool_path, pass_speeds)
    if problem is None:
        yield Chunk(W[:1].copy(), np.zeros((1, 6)), tuple((0, i) for i in index))
        return
    path, grid, _, caps, rows, keep, of_waypoint = problem
    pieces = _Pieces(path, grid, caps, rows, limits.acceleration, stretch, horizon)
    window = 2.0 * float(np.max(limits.acceleration / limits.jerk))
    knots = path.s[of_waypoint]
    where = index[keep]
    given = judged = frozen = rounds = 0
    marked = 0                                      # waypoints marked so far
    pieces.more()
    while True:
        raw = joined(grid, pieces.kept)
        filtered = FilteredProfile(raw, window)
        done = pieces.kept[-1].last == len(grid) - 1
        last = math.ceil(filtered.duration / dt - 1e-9) if done else int(raw.duration / dt)
        lo = min(given, max(judged - 3, 0))
        t = np.arange(lo, last + 1) * dt
        s, sd = filtered.sample(t)
        q, dq = path.evaluate(s, (0, 1))
        v = dq * sd[:, None]
        if lo == 0:
            q[0], v[0] = W[0], 0.0
        if done:
            q[-1], v[-1] = W[-1], 0.0
        check_range(q, limits, where[path_piece(path, s)])
        excess = excess_per_sample(q, v, dt, limits, tool_path)
        # The samples judged now: past those judged before (the three before them, held at
        # rest by the check, are context), short of the last unless it is the end.
        judge = np.zeros(len(q), dtype=bool)
        judge[judged - lo:len(q) - (0 if done else 1)] = True
        speed = np.where(judge, excess.per_sample("speed"), 0.0)
        accel = np.where(judge, np.maximum(excess.per_sample("acceleration"),
                                           excess.per_sample("jerk")), 0.0)
        if max(speed.max(), accel.max()) > 1.0 + LIMIT_SLACK:
            rounds += 1
            if rounds > _MAX_ROUNDS:
                worst = int(np.argmax(np.maximum(speed, accel)))
                raise PlanningError("LIMITS", "the sampled motion stays above the limits after "
                                    "slowing it down",
                                    index=int(where[path_piece(path, s[worst:worst + 1])[0]]))
            seam = pieces.slow_down(raw, window, t, speed, accel, frozen)
            judged = min(judged, int(raw.times[seam] / dt) + 1)
            continue
        rounds = 0
        judged = lo + int(np.flatnonzero(judge)[-1]) + 1 if judge.any() else judged
        if done and judged == last + 1:
            give = last + 1
        else:
            frozen = pieces.seam_before(raw, (judged - 1) * dt - window - 3 * dt - LAG, frozen)
            give = min(judged, int(raw.times[frozen] / dt) + 1)
        if give > given and (frozen > 0 or give == last + 1):   # not the start alone
            rows_s = s[given - lo:give - lo]
            marks = []
            final = give == last + 1
            while marked < len(W) and (final or knots[marked] <= rows_s[-1] + 1e-12):
                row = min(int(np.searchsorted(rows_s, knots[marked] - 1e-12)), len(rows_s) - 1)
                marks.append((given + row, marked))
                marked += 1
            yield Chunk(q[given - lo:give - lo], v[given - lo:give - lo], tuple(marks))
            given = give
        if done and given == last + 1:
            return
        if not done:
            pieces.more()


class _Pieces:
    """The raw pieces kept so far (horizon.py), and the limits they are timed with, lowered
    where samples exceeded."""

    def __init__(self, path, grid, caps, rows, acceleration, stretch: float, horizon: float):
        self.path, self.grid, self.rows = path, grid, rows
        self.caps = caps.copy()
        self.accel = np.tile(acceleration, (len(grid) - 1, 1))
        self.stretch, self.horizon = stretch, horizon
        self.kept: list[RawStretch] = []
        self._next = self._from(0)

    def _from(self, seam: int) -> Iterator[RawStretch]:
        x = float(self.kept[-1].xs[-1]) if self.kept else 0.0
        return raw_in_stretches(self.path, self.grid, self.accel, self.caps, self.rows,
                                stretch=self.stretch, horizon=self.horizon, first=seam,
                                x_start=x)

    def more(self) -> None:
        self.kept.append(next(self._next))

    def seams(self) -> list[int]:
        return [0, *(piece.last for piece in self.kept)]

    def seam_before(self, raw, time: float, at_least: int) -> int:
        """The latest seam reached by `time` (s, on the raw profile), and at least at_least."""
        return max([at_least, *(i for i in self.seams() if raw.times[i] <= time)])

    def slow_down(self, raw, window: float, t: np.ndarray, speed: np.ndarray,
                  accel: np.ndarray, frozen: int) -> int:
        """Limits lowered behind the samples at t that exceed (their ratios speed, accel), and
        the pieces timed again from the last seam before the first lowered stage (not before
        `frozen`); returns that seam."""
        n = len(raw.grid)
        caps, limits = slowed_where_exceeded(raw, window, t, speed, accel, self.caps[:n],
                                             self.accel[:n - 1])
        lowered = np.flatnonzero((caps < self.caps[:n]) | np.append(
            np.any(limits < self.accel[:n - 1], axis=1), False))
        if self.rows is not None:   # the tool's acceleration rows lowered as the joints'
            need = np.max(self.accel[:n - 1] / limits, axis=1)
            at_point = np.maximum(np.append(need, 1.0), np.insert(need, 0, 1.0))[frozen + 1:]
            ku, kx, h = self.rows
            ku, kx = ku.copy(), kx.copy()
            ku[frozen + 1:n] *= at_point[:, None]
            kx[frozen + 1:n] *= at_point[:, None]
            self.rows = (ku, kx, h)
        self.caps[frozen + 1:n] = caps[frozen + 1:]         # the frozen stages stay as played
        self.accel[frozen:n - 1] = limits[frozen:]
        first = max(int(lowered[0]) - 1, frozen) if lowered.size else frozen
        reach = self.kept[-1].last
        before = [i for i in self.seams() if frozen <= i <= first]
        for seam in reversed(before):   # a seam's speed may be above what the lower limits
            try:                        # can brake from: then the one before it
                self._retime(seam, reach)
                return seam
            except PlanningError:
                continue
        raise PlanningError("LIMITS", "the motion cannot be slowed down where its samples "
                            "exceed a limit without changing rows already given out")

    def _retime(self, seam: int, reach: int) -> None:
        self.kept = [piece for piece in self.kept if piece.last <= seam]
        self._next = self._from(seam)
        while not self.kept or self.kept[-1].last < reach:
            self.more()
