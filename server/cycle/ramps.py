"""Ramps of the play rate along a planned trajectory (playback.py): stops and resumes that keep
every joint within its acceleration and jerk limits, planned by ruckig in the path parameter.

The play position sigma (samples of the trajectory) is one degree of freedom; ruckig plans its
jerk-limited, time-optimal change from the play's state (sigma, rate, rate change) to a new
rate: 0 (a stop: velocity control, wherever it comes to rest) or 1 (a resume: position control
onto a whole sample, reached at full rate after a whole number of cycles, so that the play goes
on with the planned samples exactly). Units here are samples and cycles (ruckig's time step is
one cycle).

The bounds come from the path: a joint moving dq/dsigma rad per sample accelerates at
dq/dsigma * d2sigma/dt2 when the rate changes, so d2sigma/dt2 <= a dt^2 / |dq/dsigma| and its
jerk <= j dt^3 / |dq/dsigma| over the stretch the ramp covers. That is exact while the planned
motion cruises; where it accelerates or bends, its own acceleration and jerk add to the ramp's
(a r^2 + v dr/dt, j r^3 + 3 a r dr/dt + v d2r/dt2), with signs that may help or not. So every
ramp is checked before it is played: the positions it commands, after the three cycles played
before it and followed by the rest (held at rest, or the samples that follow a resume), must
keep the second and third differences within the limits. A ramp that does not is planned
again with bounds lower by RETRY, at most ATTEMPTS times a cycle; then the play goes on as it
was and tries again next cycle (the planned motion is then at its own limits: braking harder
than it does is not possible just then).
"""
from __future__ import annotations

import math

import numpy as np
from ruckig import (ControlInterface, DurationDiscretization, InputParameter, Result, Ruckig,
                    Trajectory)

ATTEMPTS = 3        # ramps planned and checked in one cycle, at most
STEADY_RATES = (0.5, 0.25)   # a resume in steps: the rates held meanwhile
STOP_SCALES = (1.0, 0.85, 0.7, 0.5)   # a stop's bounds from the speed now, tried in turn
CALM = 7            # samples in a row where the planned motion leaves a resume room
RETRY = 0.6         # the bounds of the next attempt, against the last one's
SLACK = 1e-9        # relative: what rounding may add to a checked value
# Cycles a ramp may take, at most (9 minutes at 4 ms: a stop from full speed at 0.1 % of the
# acceleration takes about one): a longer one is refused, not sampled cycle by cycle (at bounds
# low enough, that asked for gigabytes and minutes inside a cycle).
MAX_CYCLES = 1 << 17


def sampled(trajectory: Trajectory, cycles: int) -> np.ndarray:
    """(cycles + 1, 3) position, velocity and acceleration of a one-DOF ruckig trajectory at
    whole cycles (its time unit), from its phases at once (at_time per cycle costs the cycle
    more than the rest of a ramp's planning). As at_time: a brake phase first if the state was
    past the bounds; past the end the final acceleration is kept (zero jerk)."""
    profile = trajectory.profiles[0][0]
    brake = profile.brake
    used = [k for k in range(2) if brake.duration > 0.0 and brake.t[k] > 0.0]
    durations = np.array([brake.t[k] for k in used] + list(profile.t))
    j, a, v, p = (np.array([getattr(brake, name)[k] for k in used]
                           + list(getattr(profile, name))[:7])
                  for name in ("j", "a", "v", "p"))
    times = np.arange(cycles + 1, dtype=float)
    edges = np.concatenate([[0.0], np.cumsum(durations)])
    i = np.clip(np.searchsorted(edges, times, side="right") - 1, 0, len(durations) - 1)
    r = np.minimum(times, trajectory.duration) - edges[i]
    states = np.stack([p[i] + r * (v[i] + r * (a[i] / 2.0 + r * j[i] / 6.0)),
                       v[i] + r * (a[i] + r * j[i] / 2.0), a[i] + r * j[i]], axis=1)
    past = np.maximum(times - trajectory.duration, 0.0)
    states[:, 0] += past * (states[:, 1] + past * states[:, 2] / 2.0)
    states[:, 1] += past * states[:, 2]
    return states


def hermite(positions: np.ndarray, sigma: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions (K, M) and their derivatives per sample (K, M) at play positions sigma (K,) on
    the samples (N, M) of M joints: the quintic Hermite curve through them, with each sample's
    velocity and acceleration from central differences (the trajectory held at rest past its
    ends). Exact at whole samples, C2 between them."""
    n = len(positions)
    if n == 1:
        held = np.repeat(positions, len(sigma), axis=0)
        return held, np.zeros_like(held)
    i = np.clip(np.floor(sigma).astype(int), 0, n - 2)
    weights = _weights((sigma - i)[:, None])
    rows = [positions[np.clip(i + k, 0, n - 1)] for k in (-1, 0, 1, 2)]
    return (sum(w * row for w, row in zip(weights[:4], rows)),
            sum(w * row for w, row in zip(weights[4:], rows)))


def hermite_at(positions: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray]:
    """`hermite` at one play position, as the cycle asks for it every cycle: at a whole sample
    (the play at its planned pace) the sample and its central difference, else the curve's
    weights in floats times the four rows at once (the array form's small numpy calls would
    cost the cycle more than its physics). Read-only: the position may be a view of
    `positions`."""
    n = len(positions)
    if n == 1:
        return positions[0], np.zeros_like(positions[0])
    if sigma == (k := int(sigma)) and 0 <= k < n:
        return positions[k], (positions[min(k + 1, n - 1)] - positions[max(k - 1, 0)]) * 0.5
    i = min(max(math.floor(sigma), 0), n - 2)
    rows = (positions[i - 1:i + 3] if 1 <= i <= n - 3
            else positions[[max(i - 1, 0), i, i + 1, min(i + 2, n - 1)]])
    curve = np.array(_weights(sigma - i)).reshape(2, 4) @ rows
    return curve[0], curve[1]


def _weights(t):
    """The weights of the four samples around the play position (the one before, the two it
    lies between, the one after) in the curve, then in its derivative, at fraction t between
    the middle two: floats, or arrays of them. The quintic Hermite basis, with each sample's
    velocity (p[k+1] - p[k-1]) / 2 and acceleration p[k+1] - 2 p[k] + p[k-1] put in."""
    t2 = t * t
    t3 = t2 * t
    t4, t5 = t3 * t, t3 * t2
    h0 = 1 - 10 * t3 + 15 * t4 - 6 * t5            # the basis: at the first sample
    h1 = t - 6 * t3 + 8 * t4 - 3 * t5              # its velocity
    h2 = t2 / 2 - 1.5 * t3 + 1.5 * t4 - t5 / 2     # its acceleration
    h3 = t3 / 2 - t4 + t5 / 2                      # the second's acceleration
    h4 = -4 * t3 + 7 * t4 - 3 * t5                 # its velocity
    h5 = 10 * t3 - 15 * t4 + 6 * t5               # the second sample
    d0 = -30 * t2 + 60 * t3 - 30 * t4              # their derivatives (d5 = -d0)
    d1 = 1 - 18 * t2 + 32 * t3 - 15 * t4
    d2 = t - 4.5 * t2 + 6 * t3 - 2.5 * t4
    d3 = 1.5 * t2 - 4 * t3 + 2.5 * t4
    d4 = -12 * t2 + 28 * t3 - 15 * t4
    return (h2 - h1 / 2, h0 - 2 * h2 + h3 - h4 / 2, h5 + h1 / 2 + h2 - 2 * h3, h3 + h4 / 2,
            d2 - d1 / 2, d0 - 2 * d2 + d3 - d4 / 2, -d0 + d1 / 2 + d2 - 2 * d3, d3 + d4 / 2)


class RampPlanner:
    """Plans and checks ramps for one motion (its ruckig objects, reused)."""

    def __init__(self, dt: float):
        self.dt = dt
        self._otg = Ruckig(1, 1.0)
        self._input = InputParameter(1)
        self._trajectory = Trajectory(1)
        self._tries = 0     # ramps tried since the last one that fitted: where to go on

    def plan(self, positions: np.ndarray, recent: np.ndarray, sigma: float, rate: float,
             change: float, target: float, acceleration: np.ndarray, jerk: np.ndarray):
        """(sigma, rate, rate change) per cycle (L + 1,) from now (index 0) to the ramp's end,
        or None if no ramp fits this cycle. positions (N, 6): the segment; recent (3, 6): the
        positions played in the last three cycles, newest first; acceleration, jerk (6,):
        rad/s^2 and rad/s^3.

        A stop tries the time-optimal ramp with lower and lower bounds. A resume must end where
        the planned motion leaves room to reach full rate (not where it accelerates at its
        limit: a rate still rising would add to that): it tries the time-optimal ramp, then
        ramps in steps: up to a steady lower rate (STEADY_RATES: the planned motion's own
        acceleration then takes at most its square of the limit), held until a calm stretch
        of the planned motion, and up to full rate there."""
        last = len(positions) - 1
        if last < 1 or not 0.0 <= sigma <= last:
            return None     # no stretch to ramp along
        if target == 0.0:
            # Bounds from the speed now first (a planned motion that speeds up meanwhile adds
            # less than its speed-up, the rate falling), then from the fastest the stop covers.
            options = [(1.0, "joint"), *((scale, "now") for scale in STOP_SCALES),
                       (0.85, "joint"), *((RETRY ** k, None) for k in range(ATTEMPTS))]
        else:
            calm = self._calm(positions, sigma, acceleration, jerk)
            options = [(1.0, None), *((steady, start) for start in calm
                                      for steady in STEADY_RATES),
                       *((RETRY ** k, None) for k in range(1, 4)),
                       *((RETRY ** k, "end") for k in range(6))]   # down to 0.08: one fits
        for k in range(min(ATTEMPTS, len(options))):
            option = options[(self._tries + k) % len(options)]
            if option[1] == "joint":
                ramp = self._stop_along_joint(positions, sigma, rate, change, acceleration,
                                              jerk, option[0])
            elif option[1] in (None, "now", "end"):
                ramp = self._planned(positions, sigma, rate, change, target, acceleration,
                                     jerk, option[0], now=option[1] == "now",
                                     to_end=option[1] == "end")
            else:
                ramp = self._by_steps(positions, sigma, rate, change, acceleration, jerk,
                                      *option)
            if ramp is None and target == 0.0 and option[1] != "joint":
                return None       # the segment ends first: it comes to rest as planned
            if ramp is not None and self._fits(positions, recent, ramp, target, acceleration,
                                               jerk):
                self._tries = 0
                return ramp
        self._tries += ATTEMPTS
        return None

    def _calm(self, positions: np.ndarray, sigma: float, acceleration: np.ndarray,
              jerk: np.ndarray, count: int = 4, ahead: int = 1000) -> list[tuple[int, int]]:
        """Stretches (first, last sample) after sigma where a resume may reach full rate: every
        joint's planned acceleration below half its limit or braking, its jerk below half its
        limit; at least CALM samples long, the first `count` of them."""
        last = len(positions) - 1
        lo, hi = int(sigma) + 4, min(last - 3, int(sigma) + ahead)
        if hi - lo < CALM:
            return []
        window = positions[lo - 3:hi + 3]
        dt = self.dt
        step = np.diff(window, axis=0)
        accel = np.diff(window, 2, axis=0)                 # at samples lo-2 .. hi+1
        third = np.abs(np.diff(window, 3, axis=0))
        braking = accel * step[1:] <= 0.0
        ok = (braking | (np.abs(accel) <= 0.5 * acceleration * dt * dt)).all(axis=1)
        ok = ok[:len(third)] & (third <= 0.5 * jerk * dt ** 3).all(axis=1)
        edges = np.flatnonzero(np.diff(np.concatenate([[0], ok.astype(int), [0]])))
        runs = [(int(a) + lo - 2, int(b) + lo - 4) for a, b in zip(edges[::2], edges[1::2])
                if b - a >= CALM]
        return runs[:count]

    def _stop_along_joint(self, positions, sigma, rate, change, acceleration, jerk, scale):
        """A stop planned for the fastest joint: its own time-optimal jerk-limited stop
        (ruckig, its limits times `scale`), the play position following it along the path
        (the inverse of that joint's motion, monotone while it brakes). Exact on a straight
        joint line, where a time warp with constant bounds brakes late (the planned motion's
        speed-up, which it must also undo, fades as the rate falls); or None."""
        last, dt = len(positions) - 1, self.dt
        here = np.array([sigma - 1e-3, sigma, sigma + 1e-3])
        q, slope = hermite(positions, here)
        k = int(np.argmax(np.abs(slope[1]) / acceleration))
        if abs(slope[1, k]) < 1e-9 or rate <= 0.0:
            return None
        sign = math.copysign(1.0, slope[1, k])
        curve = (slope[2, k] - slope[0, k]) / 2e-3                  # d2q/dsigma2
        inp = self._input
        inp.current_position = [float(sign * q[1, k])]
        inp.current_velocity = [float(sign * slope[1, k] * rate)]
        inp.current_acceleration = [float(sign * (curve * rate * rate + slope[1, k] * change))]
        inp.max_velocity = [max(inp.current_velocity[0], 1e-9) * 2.0]
        inp.max_acceleration = [scale * float(acceleration[k]) * dt * dt]
        inp.max_jerk = [scale * float(jerk[k]) * dt ** 3]
        inp.target_velocity, inp.target_acceleration = [0.0], [0.0]
        inp.control_interface = ControlInterface.Velocity
        inp.duration_discretization = DurationDiscretization.Continuous
        if not self._calculated():
            return None
        trajectory = self._trajectory
        cycles = max(1, int(math.ceil(trajectory.duration - 1e-9)))
        states = sampled(trajectory, cycles)
        wanted, speed = states[:, 0], states[:, 1]
        # Where along the path the joint is there: search the samples, then Newton on the curve.
        hi = min(last, int(sigma) + 2 + int(math.ceil(cycles * max(rate, 1e-9))) * 2)
        along = sign * positions[int(sigma):hi + 1, k]
        if np.any(np.diff(along) < 0.0) or wanted[-1] > along[-1]:
            return None        # the joint turns back, or the segment ends first
        guess = int(sigma) + np.clip(np.searchsorted(along, wanted) - 1, 0, len(along) - 2)
        found = np.maximum(guess + (wanted - along[guess - int(sigma)]) / np.maximum(
            along[guess - int(sigma) + 1] - along[guess - int(sigma)], 1e-15), sigma)
        joint = positions[:, k:k + 1]         # the curve of that joint alone: a sixth the cost
        for _ in range(3):
            value, d = hermite(joint, found)
            found = np.clip(found - (sign * value[:, 0] - wanted)
                            / np.where(np.abs(d[:, 0]) > 1e-15, sign * d[:, 0], np.inf),
                            sigma, last)
        found[0] = sigma
        found = np.maximum.accumulate(found)
        d = sign * hermite(joint, found)[1][:, 0]
        rates = np.where(d > 1e-15, speed / np.maximum(d, 1e-15), 0.0)
        rates[0], rates[-1] = rate, 0.0
        changes = np.gradient(rates)
        changes[0], changes[-1] = change, 0.0
        return found, rates, changes

    def _by_steps(self, positions, sigma, rate, change, acceleration, jerk, steady, calm):
        """A resume in three steps: up to the steady rate, held until the calm stretch `calm`
        (first, last sample), up to full rate within it; or None."""
        # The planned motion's own acceleration takes up to steady^2 of the limit meanwhile,
        # and in the calm stretch up to half of it: the ramps keep to what is left.
        first = self._planned(positions, sigma, rate, change, steady, acceleration, jerk,
                              0.9 * (1.0 - steady * steady))
        if first is None or first[0][-1] >= calm[0]:
            return None
        held = max(1, int(math.ceil((calm[0] - first[0][-1]) / steady)))
        sigma_held = first[0][-1] + steady * np.arange(1, held + 1)
        last = self._planned(positions, float(sigma_held[-1]), steady, 0.0, 1.0, acceleration,
                             jerk, 0.45, calm[1])
        if last is None:
            return None
        return tuple(np.concatenate([a, b, c[1:]]) for a, b, c in zip(
            first, (sigma_held, np.full(held, steady), np.zeros(held)), last))

    def _planned(self, positions, sigma, rate, change, target, acceleration, jerk, scale,
                 reach=None, now=False, to_end=False):
        """A ramp with bounds from the stretch it covers (times `scale`; from the samples
        around sigma alone if `now`; a resume must land by sample `reach`, or with `to_end`
        goes through to the segment's end, at rest), or None."""
        last, dt = len(positions) - 1, self.dt
        lo = int(sigma)
        window = lo + 3
        bounds = ramp = None
        for _ in range(1 if now else 2):    # the stretch the ramp covers decides its bounds
            stretch = positions[max(lo - 1, 0):min(window, last) + 1]
            if len(stretch) < 2:
                return None    # past the segment's end: nothing to take the bounds from
            step = np.abs(np.diff(stretch, axis=0))
            fastest = np.maximum(step.max(axis=0), 1e-12)          # rad per sample
            wanted = (scale * float(np.min(acceleration * dt * dt / fastest)),
                      scale * float(np.min(jerk * dt ** 3 / fastest)))
            if bounds is not None and wanted[0] >= bounds[0] and wanted[1] >= bounds[1]:
                break
            bounds = wanted
            ramp = self._ruckig(sigma, rate, change, target, bounds, last, to_end)
            if ramp is None or (reach is not None and ramp[0][-1] > reach):
                return None
            window = int(math.ceil(ramp[0][-1])) + 2
        return ramp

    def _ruckig(self, sigma: float, rate: float, change: float, target: float,
                bounds: tuple[float, float], last: int, to_end: bool = False):
        """The ramp as (sigma, rate, change) at whole cycles, or None (it would leave the
        segment: a stop then lets the segment end at rest, as planned)."""
        inp = self._input
        inp.current_position, inp.current_velocity = [sigma], [rate]
        inp.current_acceleration = [change]
        inp.max_velocity, inp.max_acceleration, inp.max_jerk = [1.0], [bounds[0]], [bounds[1]]
        inp.target_velocity, inp.target_acceleration = [target], [0.0]
        inp.control_interface = ControlInterface.Velocity
        inp.duration_discretization = DurationDiscretization.Continuous
        if not self._calculated():
            return None
        end = self._trajectory.at_time(self._trajectory.duration)[0][0]
        if target == 1.0:   # a resume: onto a whole sample at full rate, or to the end at rest
            landing = math.ceil(end) + 1
            inp.control_interface = ControlInterface.Position
            inp.duration_discretization = DurationDiscretization.Discrete
            if landing + 3 <= last and not to_end:
                inp.target_position, inp.target_velocity = [float(landing)], [1.0]
            else:
                inp.target_position, inp.target_velocity = [float(last)], [0.0]
            if not self._calculated():
                return None
        elif end > last:
            return None
        trajectory = self._trajectory
        cycles = max(1, int(math.ceil(trajectory.duration - 1e-9)))
        states = sampled(trajectory, cycles)
        if target == 1.0:
            states[-1, 0] = round(states[-1, 0])    # the landing sample, exactly
            states[-1, 1:] = (1.0 if states[-1, 0] < last else 0.0), 0.0
        else:
            states[-1, 1:] = target, 0.0
        return states[:, 0], states[:, 1], states[:, 2]

    def _calculated(self) -> bool:
        """Whether ruckig planned the input into the trajectory, within MAX_CYCLES. Its Python
        binding raises ValueError for the results its enum lacks (-101, the duration beyond
        ruckig's numerical range): a refusal like any other."""
        try:
            result = self._otg.calculate(self._input, self._trajectory)
        except ValueError:
            return False
        return (result in (Result.Working, Result.Finished)
                and self._trajectory.duration <= MAX_CYCLES)

    def _fits(self, positions: np.ndarray, recent: np.ndarray, ramp, target: float,
              acceleration: np.ndarray, jerk: np.ndarray) -> bool:
        """Whether the ramp's commanded positions keep the limits, with the three cycles before
        it and those after (at rest, or the planned samples that follow a resume)."""
        sigma, rate = ramp[0], ramp[1]
        last = len(positions) - 1
        end = sigma[-1]
        going = target > 0.0 and rate[-1] > 0.0
        after = np.minimum(end + np.arange(1, 4), last) if going else np.full(2, end)
        new, slope = hermite(positions, np.concatenate([sigma, after]))
        seq = np.concatenate([recent[::-1], new[1:]])
        dt = self.dt
        second = np.abs(np.diff(seq[1:], 2, axis=0))
        third = np.abs(np.diff(seq, 3, axis=0))
        # The commanded velocities (playback.Motion.velocity) change within the limit too.
        velocity = slope * np.concatenate([rate, np.full(len(after), rate[-1])])[:, None]
        change = np.abs(np.diff(velocity, axis=0))
        return bool(np.all(second <= acceleration * dt * dt * (1 + SLACK))
                    and np.all(third <= jerk * dt ** 3 * (1 + SLACK))
                    and np.all(change <= acceleration * dt * dt * (1 + SLACK)))
