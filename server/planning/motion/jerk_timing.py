"""Jerk-limited timing along a path: TOPP-RA's profile, made flat at its turns, then filtered.

TOPP-RA (topp_ra.py) times a path time-optimally under velocity and acceleration limits; its
path acceleration u = d2s/dt2 is constant per stage and jumps between stages, so its joint
jerk is unbounded. Here the profile is re-timed in the path parameter s, which keeps the
geometry (every sample stays on the path):

1. A moving average of s(t) over a window T (a finite-impulse-response jerk filter, as CNC
   controllers use): s_T(t) = (1/T) integral of s over [t - T, t]. Its path acceleration is
   the average of u over the window and its path jerk (u(t) - u(t - T)) / T, so a jump of u by
   at most T times the jerk limit becomes a ramp within the limit; a rest-to-rest motion
   lasts T longer. T is the time the limits take to ramp the acceleration up
   (max_acceleration / max_jerk: 20 ms for the TX90).
2. Where the profile turns (a peak of the speed, where u jumps from accelerating to braking,
   or a valley), u would jump by twice the acceleration limit; `flat_turns` caps the speed
   there so that the profile stays flat for at least T first: the jumps become two, each
   within the filter's reach, at the cost of about T / 2 (the jerk-limited optimum of a short
   rest-to-rest move costs about the ramp time as well). A path with many turns rather takes
   a window of 2 T, which spreads a jump from one limit to the other within the jerk limit
   and costs T once, not T / 2 per turn (timing.py chooses).
3. The path's own curvature adds jerk at any path acceleration (d3q/ds3 sdot^3): `jerk_caps`
   bounds the squared speed so that it takes at most half of each joint's limit.

What remains is checked on the samples (sample_check.py: third differences of the positions,
the arm held at rest before and after). Where a sample exceeds a limit (the filter moves
the profile along the path a little, and the curvature's share of the jerk varies),
`slowed_where_exceeded` lowers TOPP-RA's acceleration limits (or speed caps) on the stages
behind that sample only, and TOPP-RA plans again: a few rounds, then whatever still exceeds
is slowed down uniformly (timing.py). Slowing the whole section for one local excess cost
blended paths 4 to 7 % of their time; locally, 1 to 2 %.
"""
from __future__ import annotations

import math

import numpy as np

from .topp_ra import ConstAccelProfile
from .trajectory import JointPath

__all__ = ["FilteredProfile", "flat_turns", "jerk_caps", "slowed_where_exceeded",
           "CURVATURE_SHARE", "SLOW_DOWN_MARGIN"]

CURVATURE_SHARE = 0.5     # of each joint's jerk limit the path's curvature may take
SLOW_DOWN_MARGIN = 0.01   # relative: below the limit a local slow-down aims, past the excess


class FilteredProfile:
    """s(t) of a ConstAccelProfile averaged over a window of `window` s, in closed form (the
    integral of a piecewise-quadratic s(t) is piecewise cubic): `duration`, and `sample(t)`
    -> (s, ds/dt) as ConstAccelProfile's."""

    def __init__(self, profile: ConstAccelProfile, window: float):
        self.profile, self.window = profile, window
        h = np.diff(profile.times)
        g, sd, u = profile.grid, profile.sd, profile.u
        # The integral of s from 0 to each stage's start.
        self._area = np.concatenate([[0.0], np.cumsum(g[:-1] * h + sd[:-1] * h**2 / 2.0
                                                      + u * h**3 / 6.0)])
        self.duration = profile.duration + window

    def _raw(self, t: np.ndarray):
        """s, ds/dt and the integral of s from 0, of the unfiltered profile at times t (held
        at its ends before 0 and after its duration)."""
        p = self.profile
        inside = np.clip(t, 0.0, p.duration)
        i = np.clip(np.searchsorted(p.times, inside, side="right") - 1, 0, len(p.u) - 1)
        r = inside - p.times[i]
        sd0, u, s0 = p.sd[i], p.u[i], p.grid[i]
        s = s0 + r * (sd0 + 0.5 * u * r)
        area = self._area[i] + r * (s0 + r * (sd0 / 2.0 + u * r / 6.0)) + p.grid[-1] * (t - inside)
        moving = (t > 0.0) & (t < p.duration)
        return (np.where(t <= 0.0, p.grid[0], s), np.where(moving, sd0 + u * r, 0.0),
                np.where(t <= 0.0, p.grid[0] * t, area))

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        s1, _, a1 = self._raw(t)
        s0, _, a0 = self._raw(t - self.window)
        return (a1 - a0) / self.window, (s1 - s0) / self.window


def flat_turns(grid: np.ndarray, xs: np.ndarray, caps: np.ndarray, window: float) -> np.ndarray:
    """(G,) caps on the squared path speed x that keep the profile xs (G,) flat for at least
    `window` s at each of its peaks and valleys: a peak is cut to the level at which the stretch
    above it lasts that long; a valley's speed is held over a stretch that long around it,
    unless the valley is one of the speed caps (G,) TOPP-RA kept (a pass speed: flat by then)."""
    cap = np.full(len(xs), np.inf)
    last = len(xs) - 1
    inner = np.arange(1, last)
    peaks = inner[(xs[inner - 1] < xs[inner]) & (xs[inner] >= xs[inner + 1])]
    valleys = inner[(xs[inner - 1] > xs[inner]) & (xs[inner] <= xs[inner + 1])]
    x, g = xs.tolist(), grid.tolist()
    for i in peaks.tolist():
        lo = hi = i
        level = x[i]
        while g[hi] - g[lo] < math.sqrt(level) * window and (lo > 0 or hi < last):
            if hi == last or (lo > 0 and x[lo - 1] >= x[hi + 1]):
                lo -= 1
            else:
                hi += 1
            level = min(x[lo], x[hi])
        if level <= 0.0:   # a rest end reached first (a short move): the speed that lasts so
            level = min(x[i], ((g[hi] - g[lo]) / window) ** 2)
        cap[lo:hi + 1] = np.minimum(cap[lo:hi + 1], level)
    capped = xs >= caps * (1.0 - 1e-9)
    for i in valleys[~capped[valleys]].tolist():
        reach = 0.5 * math.sqrt(max(x[i], 0.0)) * window
        lo, hi = np.searchsorted(grid, [g[i] - reach, g[i] + reach])
        cap[max(lo - 1, 0):hi + 1] = np.minimum(cap[max(lo - 1, 0):hi + 1], x[i])
    return cap


def jerk_caps(path: JointPath, grid: np.ndarray, jerk: np.ndarray) -> np.ndarray:
    """(G,) the squared path speed x at which the path's curvature alone takes
    CURVATURE_SHARE of each joint's jerk limit: |d3q/ds3| sdot^3 <= share * jerk."""
    third = np.abs(path.evaluate(grid, (3,))[0])
    # d3q/ds3 is constant on each spline piece: a gridpoint at a knot takes the larger side.
    before = np.abs(path.evaluate(np.maximum(grid - 1e-9, path.s[0]), (3,))[0])
    third = np.maximum(third, before)
    with np.errstate(divide="ignore"):
        x = np.min((CURVATURE_SHARE * jerk / third) ** (2.0 / 3.0), axis=1)
    return np.minimum(x, 1e300)


def slowed_where_exceeded(raw: ConstAccelProfile, window: float, times: np.ndarray,
                          speed: np.ndarray, acceleration: np.ndarray, caps: np.ndarray,
                          limits: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The speed caps (G,) and the per-stage acceleration limits (G-1, 6) TOPP-RA plans with,
    lowered where samples of the filtered profile exceeded a limit: its samples at profile
    times `times` (K,), with their ratios to the limits (Excess.per_sample): `speed` (K,)
    (velocity-like, 1/k) and `acceleration` (K,) (the larger of the acceleration and jerk
    ratios: both shrink in proportion as the path acceleration does, to first order).

    A ratio at sample k takes samples k-3 to k, and the filter's output there the raw profile
    over the window before: the stages of the raw profile in that time get their acceleration
    limits divided by the ratio (and the margin), the gridpoints their squared speed capped
    below the raw profile's by its square. Only where the samples exceed, so the rest keeps
    its time-optimal timing (a uniform slow-down pays for one excess everywhere)."""
    step = float(times[1] - times[0]) if len(times) > 1 else 0.0
    start = times - 3.0 * step - window
    need = _stage_need(raw.times, start, times, speed)
    at_point = np.maximum(np.append(need, 1.0), np.insert(need, 0, 1.0))
    x = raw.sd**2
    caps = np.where(at_point > 1.0, np.minimum(caps, x / at_point**2), caps)
    limits = limits / _stage_need(raw.times, start, times, acceleration)[:, None]
    return caps, limits


def _stage_need(stage_times: np.ndarray, start: np.ndarray, end: np.ndarray,
                ratio: np.ndarray) -> np.ndarray:
    """(S,) per stage of a profile (its S + 1 gridpoints reached at stage_times), the largest
    ratio (K,) above 1, with the margin, of those whose time span [start, end] (K,) meets the
    stage; 1 where none does."""
    stages = len(stage_times) - 1
    need = np.ones(stages)
    bad = np.flatnonzero(ratio > 1.0)
    if bad.size:
        first = np.clip(np.searchsorted(stage_times, start[bad], side="right") - 1, 0, stages - 1)
        last = np.clip(np.searchsorted(stage_times, end[bad], side="right") - 1, 0, stages - 1)
        count = last - first + 1
        index = np.repeat(first - np.cumsum(count) + count, count) + np.arange(count.sum())
        np.maximum.at(need, index, np.repeat(ratio[bad] * (1.0 + SLOW_DOWN_MARGIN), count))
    return need
