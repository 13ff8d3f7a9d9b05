"""A long section timed in stretches ahead of the play (issue 31 item 4): TOPP-RA on a receding
horizon.

time_path times a rest-to-rest section whole; for a long blended path that is most of the time
between a PathMove's handler and its first cycle. Here the section's raw TOPP-RA profile is
built stretch by stretch, so that the first stretch can be sent while the rest is timed:

- Stretch k is TOPP-RA over the gridpoints from s_k to s_k + horizon, from the squared speed
  the stretch before reached at s_k, to REST at s_k + horizon; only [s_k, s_k + stretch] is
  kept. The rest at the horizon is planned, never played: the next stretch takes over first.
- Never infeasible, never a dead stop: the speed kept at s_{k+1} could brake to rest by
  s_k + horizon, and the next horizon reaches at least as far (the arm may stay at rest there:
  an end further on only widens the controllable sets), so it lies in the next stretch's
  controllable set.
- The grid is cut, not changed: the kept pieces have the whole section's stages and
  constraints, so joined they are one profile meeting all of them. Where the horizon reaches
  past the braking distance from the top speed allowed there, the controllable sets are the
  whole section's, and the forward pass takes the same greatest x: the profile IS the whole
  section's optimum (tests/server/motion/test_horizon.py measures it).
- Raw profiles are continuous in path speed with a constant path acceleration per stage, so
  the joined pieces are a raw profile like any other; the jerk filter (FilteredProfile)
  averages s(t) over the window BEFORE t, so its samples up to the time the kept pieces reach
  are final (`final_until`) and can be played while the rest is timed.
"""
from __future__ import annotations

from collections.abc import Iterator
from typing import NamedTuple

import numpy as np

from .topp_ra import ConstAccelProfile, topp_ra
from .trajectory import JointPath

__all__ = ["RawStretch", "raw_in_stretches", "joined", "final_until"]


class RawStretch(NamedTuple):
    """A kept piece of the profile: squared path speeds xs at gridpoints first.. of the grid
    (its first one is the previous piece's last: the pieces share their seams)."""

    first: int
    xs: np.ndarray

    @property
    def last(self) -> int:
        return self.first + len(self.xs) - 1


def raw_in_stretches(path: JointPath, grid: np.ndarray, acceleration: np.ndarray,
                     caps: np.ndarray, rows=None, *, stretch: float, horizon: float,
                     first: int = 0, x_start: float = 0.0) -> Iterator[RawStretch]:
    """The profile to rest along `path` over `grid`, as topp_ra's arguments (acceleration
    (6,) or a row per stage, caps (G,), rows), kept `stretch` of path (rad of s) at a time,
    each timed over `horizon` (> stretch) ahead of its start; from gridpoint `first` at the
    squared speed x_start (a seam of pieces kept before). Lazy: each piece is timed when asked
    for, so a caller sends one before the next is timed."""
    if not 0 < stretch < horizon:
        raise ValueError(f"need 0 < stretch < horizon, got {stretch!r}, {horizon!r}")
    acceleration = np.asarray(acceleration, dtype=float)
    last = len(grid) - 1
    while first < last:
        keep = _at_least_one_after(grid, first, stretch)
        end = max(_at_least_one_after(grid, first, horizon), keep + 1) if keep < last else last
        accel = acceleration[first:end] if acceleration.ndim == 2 else acceleration
        part_rows = None if rows is None else (rows[0][first:end + 1], rows[1][first:end + 1],
                                               rows[2])
        xs = topp_ra(path, grid[first:end + 1], accel, caps[first:end + 1], part_rows,
                     x_start=x_start)
        kept = xs[:keep - first + 1]
        yield RawStretch(first, kept)
        first, x_start = keep, float(kept[-1])


def _at_least_one_after(grid: np.ndarray, first: int, length: float) -> int:
    """The first gridpoint at least `length` past grid[first] (at least first + 1), or the
    last one."""
    at = int(np.searchsorted(grid, grid[first] + length))
    return min(max(at, first + 1), len(grid) - 1)


def joined(grid: np.ndarray, pieces: list[RawStretch]) -> ConstAccelProfile:
    """The kept pieces so far (in order, from the first) as one profile over their gridpoints."""
    xs = np.concatenate([pieces[0].xs, *(piece.xs[1:] for piece in pieces[1:])])
    return ConstAccelProfile(grid[:len(xs)], xs)


def final_until(profile: ConstAccelProfile) -> float:
    """s: the time up to which the jerk filter's samples of a profile that continues `profile`
    are those of `profile` filtered (FilteredProfile: the window lies before each sample)."""
    return profile.duration
