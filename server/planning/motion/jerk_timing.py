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
   (max_acceleration / max_jerk: 20 ms for the TX90), or twice that where the path bends a lot.
2. Where the profile turns (a peak of the speed, where u jumps from accelerating to braking,
   or a valley), u would jump by twice the acceleration limit; `flat_turns` caps the speed
   there so that the profile stays flat for at least T first: the jumps become two, each
   within the filter's reach, at the cost of about T / 2 (the jerk-limited optimum of a short
   rest-to-rest move costs about the ramp time as well).
3. The path's own curvature adds jerk at any path acceleration (d3q/ds3 sdot^3): `jerk_caps`
   bounds the squared speed so that it takes at most half of each joint's limit.

What remains is checked on the samples (timing.py: third differences of the positions, the
arm held at rest before and after) and fixed by slowing down uniformly.
"""
from __future__ import annotations

import math

import numpy as np

from .topp_ra import ConstAccelProfile
from .trajectory import JointPath

__all__ = ["FilteredProfile", "flat_turns", "jerk_caps", "CURVATURE_SHARE"]

CURVATURE_SHARE = 0.5     # of each joint's jerk limit the path's curvature may take


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
