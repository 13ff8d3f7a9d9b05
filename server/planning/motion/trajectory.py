"""The records of motion planning: timed trajectories, limits, planning errors, joint paths.

Units: rad, rad/s, rad/s^2 for joints; m, m/s and rad/s for the tool tip; s for time. Joint
arrays have a last axis of 6, joint 1 first. Nothing here imports toppra or scipy.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass, field

import numpy as np

__all__ = ["Trajectory", "Limits", "PlanningError", "Reason", "JointPath"]


@dataclass(frozen=True, eq=False)   # arrays: compare by identity
class Trajectory:
    """A timed joint trajectory sampled every `dt` s: what the cycle plays, one sample per cycle.

    positions (N, 6) rad, velocities (N, 6) rad/s; sample 0 is the start (at rest unless it
    continues a motion), sample N-1 the end at rest. marks: ((sample_index, waypoint_index), ...)
    -- the sample at which each waypoint of the planned path is reached (for tag events), in
    order. Sample k is played at time k * dt after the start.
    """

    dt: float
    positions: np.ndarray
    velocities: np.ndarray
    marks: tuple[tuple[int, int], ...] = ()

    def __post_init__(self):
        if not self.dt > 0:
            raise ValueError(f"dt must be positive, got {self.dt!r}")
        if self.positions.ndim != 2 or self.positions.shape[1] != 6 or len(self.positions) < 1:
            raise ValueError(f"positions must have shape (N >= 1, 6), got {self.positions.shape}")
        if self.velocities.shape != self.positions.shape:
            raise ValueError("velocities must have the shape of positions")

    def __len__(self) -> int:
        return len(self.positions)

    @property
    def duration(self) -> float:
        """Time from the first sample to the last, s: (N - 1) * dt."""
        return (len(self.positions) - 1) * self.dt

    @property
    def times(self) -> np.ndarray:
        """(N,) s: the time of each sample after the start."""
        return np.arange(len(self.positions)) * self.dt

    def accelerations(self) -> np.ndarray:
        """(N, 6) rad/s^2: forward differences (v[k+1] - v[k]) / dt, the change of the velocity
        setpoint from one cycle to the next; the last row is 0 (the arm stays at rest)."""
        acc = np.zeros_like(self.velocities)
        acc[:-1] = np.diff(self.velocities, axis=0) / self.dt
        return acc


@dataclass(frozen=True, eq=False)
class Limits:
    """Joint limits already scaled by the set percent speed/accel (rad/s, rad/s^2, shape (6,)), and
    optional tool-tip Cartesian limits for straight/arc motions (m/s, rad/s, m/s^2, rad/s^2;
    None = none): they bound the tool tip's speed and acceleration along its path.

    position_min / position_max (6,) rad, when given, bound every sample of the timed path (a
    spline through waypoints in range may still swing out of range between them).
    """

    velocity: np.ndarray
    acceleration: np.ndarray
    linear_velocity: float | None = None
    angular_velocity: float | None = None
    linear_acceleration: float | None = None     # m/s^2 of the tool tip
    angular_acceleration: float | None = None    # rad/s^2 of the tool
    position_min: np.ndarray | None = field(default=None)
    position_max: np.ndarray | None = field(default=None)
    # The arm's own maxima (rad/s (6,), m/s), unscaled: what a waypoint's pass speed (see
    # timing.time_path) is a fraction of. None: the limits above.
    max_velocity: np.ndarray | None = field(default=None)
    max_linear_velocity: float | None = None
    # rad/s^3 (6,): every sample's third difference over dt^3 keeps it (timing.time_path then
    # times the path jerk-limited, jerk_timing.py). None: no jerk limit (bang-bang profiles).
    jerk: np.ndarray | None = field(default=None)

    def __post_init__(self):
        for name in ("velocity", "acceleration"):
            v = np.asarray(getattr(self, name), dtype=float)
            if v.shape != (6,) or not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise ValueError(f"{name} limits must be 6 positive finite values, got {v!r}")
            object.__setattr__(self, name, v)
        for name in ("linear_velocity", "angular_velocity", "linear_acceleration",
                     "angular_acceleration"):
            v = getattr(self, name)
            if v is not None and not (np.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be positive and finite, or None; got {v!r}")
        if self.jerk is not None:
            v = np.asarray(self.jerk, dtype=float)
            if v.shape != (6,) or not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise ValueError(f"jerk limits must be 6 positive finite values, got {v!r}")
            object.__setattr__(self, "jerk", v)
        for name in ("position_min", "position_max", "max_velocity"):
            v = getattr(self, name)
            if v is not None:
                v = np.asarray(v, dtype=float)
                if v.shape != (6,):
                    raise ValueError(f"{name} must have shape (6,)")
                object.__setattr__(self, name, v)

    @classmethod
    def scaled(cls, arm, speed_percent: float, accel_percent: float,
               linear_velocity: float | None = None, angular_velocity: float | None = None,
               linear_acceleration: float | None = None,
               angular_acceleration: float | None = None) -> "Limits":
        """The arm's (sim.arm.ArmModel) joint limits times speed_percent / 100 (velocity) and
        accel_percent / 100 (acceleration), percents in (0, 100].

        Cartesian limits (used when a motion passes its tool path), seed 3.2.1: the percents
        apply "globally to both joint and Cartesian moves", so the tool is held to the arm's
        Cartesian maximum times the percent; an explicit absolute value (LINEAR_SPEED,
        ANGULAR_SPEED, LINEAR_ACCEL, ANGULAR_ACCEL: m/s, rad/s, m/s^2, rad/s^2) is a cap of its
        own, NOT multiplied by the percent. The lower of the two holds. Joint ranges come from
        the arm. The jerk limits are the arm's times accel_percent / 100, so that every
        acceleration ramps up in the same time whatever the percent.
        """
        for name, p in (("speed_percent", speed_percent), ("accel_percent", accel_percent)):
            if not 0.0 < p <= 100.0:
                raise ValueError(f"{name} must be in (0, 100], got {p!r}")
        k_v, k_a = speed_percent / 100.0, accel_percent / 100.0

        def cap(maximum: float, k: float, absolute: float | None) -> float:
            return maximum * k if absolute is None else min(float(absolute), maximum * k)

        return cls(np.asarray(arm.max_velocity) * k_v, np.asarray(arm.max_acceleration) * k_a,
                   cap(arm.max_linear_velocity, k_v, linear_velocity),
                   cap(arm.max_angular_velocity, k_v, angular_velocity),
                   cap(arm.max_linear_acceleration, k_a, linear_acceleration),
                   cap(arm.max_angular_acceleration, k_a, angular_acceleration),
                   np.asarray(arm.joint_min, dtype=float), np.asarray(arm.joint_max, dtype=float),
                   np.asarray(arm.max_velocity, dtype=float), float(arm.max_linear_velocity),
                   np.asarray(arm.max_jerk) * k_a)


class Reason(enum.StrEnum):
    """Why a motion cannot be planned (compares equal to its name as a string)."""

    OUT_OF_WORKSPACE = "OUT_OF_WORKSPACE"          # no inverse kinematics solution at all
    OUT_OF_JNT_RANGE = "OUT_OF_JNT_RANGE"          # solutions, but a joint would leave its range
    SINGULARITY = "SINGULARITY"                    # the path passes (too near) a singularity
    CONFIGURATION_CHANGE = "CONFIGURATION_CHANGE"  # reachable only in another configuration
    LIMITS = "LIMITS"                              # the timing cannot meet the limits
    DEGENERATE = "DEGENERATE"                      # the geometry is undefined (collinear arc, ...)
    TOO_LONG = "TOO_LONG"                          # the timed motion lasts longer than allowed
    TOO_MANY_SAMPLES = "TOO_MANY_SAMPLES"          # a Cartesian path needs more samples than allowed


class PlanningError(ValueError):
    """Why a motion cannot be planned, with where: `index` (waypoint index) or `fraction` (0..1
    along a Cartesian segment) when known, and a `reason` code: "OUT_OF_WORKSPACE",
    "OUT_OF_JNT_RANGE", "SINGULARITY", "CONFIGURATION_CHANGE", "LIMITS", "DEGENERATE",
    "TOO_LONG", "TOO_MANY_SAMPLES"."""

    def __init__(self, reason: str, message: str = "", *, index: int | None = None,
                 fraction: float | None = None):
        self.reason = Reason(reason)
        self.message = message
        self.index = index
        self.fraction = fraction
        where = []
        if index is not None:
            where.append(f"waypoint {index}")
        if fraction is not None:
            where.append(f"at {100.0 * fraction:.1f}% of the segment")
        text = f"{self.reason.value}: {message}" if message else self.reason.value
        super().__init__(f"{text} ({', '.join(where)})" if where else text)

    def at_index(self, index: int) -> "PlanningError":
        """The same error, located at waypoint `index` (keeps the fraction)."""
        return PlanningError(self.reason, self.message, index=index, fraction=self.fraction)


class JointPath:
    """A geometric joint path: the natural C2 cubic spline through waypoints (M, 6) at path
    parameters s (M,), strictly increasing (here: the cumulative joint-space chord length, rad).

    toppra's path protocol: `path(s, order)` gives q (order 0, rad), dq/ds (1) or d2q/ds2 (2)
    at s (K,) as (K, 6); `path_interval` is [s_0, s_end]; `dof` is 6. With M = 2 the spline is
    the straight line, uniformly parametrised. The natural end conditions (d2q/ds2 = 0) make
    the path leave and reach its ends along a straight line.
    """

    def __init__(self, s: np.ndarray, waypoints: np.ndarray):
        s = np.asarray(s, dtype=float)
        y = np.asarray(waypoints, dtype=float)
        if s.ndim != 1 or len(s) < 2 or y.shape != (len(s), 6):
            raise ValueError("need s (M >= 2,) and waypoints (M, 6)")
        h = np.diff(s)
        if not np.all(h > 0):
            raise ValueError("path parameters must increase strictly")
        self.s = s
        self.waypoints = y
        self.dof = 6
        self.path_interval = np.array([s[0], s[-1]])
        m = _natural_second_derivatives(h, y)            # (M, 6): d2q/ds2 at the knots
        self.knot_curvature = m
        # Per piece i: q = c0 + t (c1 + t (c2 + t c3)), t = s - s_i; one (M-1, 4, 6) array so
        # that an evaluation gathers once.
        slope = np.diff(y, axis=0) / h[:, None]
        self._coef = np.stack([y[:-1], slope - h[:, None] * (2.0 * m[:-1] + m[1:]) / 6.0,
                               m[:-1] / 2.0, np.diff(m, axis=0) / (6.0 * h[:, None])], axis=1)

    @property
    def duration(self) -> float:   # toppra's name for the length of path_interval
        return float(self.s[-1] - self.s[0])

    def __call__(self, s, order: int = 0) -> np.ndarray:
        s = np.asarray(s, dtype=float)
        scalar = s.ndim == 0
        out = self.evaluate(np.atleast_1d(s), (order,))[0]
        return out[0] if scalar else out

    def evaluate(self, s: np.ndarray, orders=(0, 1, 2)) -> list[np.ndarray]:
        """[d^k q / ds^k at s (K,) as (K, 6) for k in orders], sharing the piece lookup."""
        i = np.clip(np.searchsorted(self.s, s, side="right") - 1, 0, len(self.s) - 2)
        t = (s - self.s[i])[:, None]
        c = self._coef[i]
        c0, c1, c2, c3 = c[:, 0], c[:, 1], c[:, 2], c[:, 3]
        out = []
        for order in orders:
            if order == 0:
                out.append(c0 + t * (c1 + t * (c2 + t * c3)))
            elif order == 1:
                out.append(c1 + t * (2.0 * c2 + 3.0 * t * c3))
            elif order == 2:
                out.append(2.0 * c2 + 6.0 * t * c3)
            elif order == 3:
                out.append(np.broadcast_to(6.0 * c3, c3.shape).copy())
            else:
                raise ValueError(f"order must be 0..3, got {order}")
        return out


def _natural_second_derivatives(h: np.ndarray, y: np.ndarray) -> np.ndarray:
    """Second derivatives (M, 6) at the knots of the natural cubic spline through y (M, 6) with
    knot spacing h (M-1,): the tridiagonal system solved by the Thomas algorithm (diagonally
    dominant, so stable without pivoting). Plain floats for the scalar recurrence: faster than
    numpy on one element at a time."""
    n = len(y)
    m = np.zeros_like(y)
    if n < 3:
        return m
    slope = np.diff(y, axis=0) / h[:, None]
    rhs = 6.0 * np.diff(slope, axis=0)                  # (n-2, 6), rows 1..n-2
    hl = h.tolist()
    diag = [2.0 * (hl[k] + hl[k + 1]) for k in range(n - 2)]
    # Forward sweep: the scalar factors first, then the right-hand sides in one pass.
    w = [0.0] * (n - 2)
    for k in range(1, n - 2):
        w[k] = hl[k] / diag[k - 1]
        diag[k] -= w[k] * hl[k]
    r = rhs.tolist()
    for k in range(1, n - 2):
        wk, prev, row = w[k], r[k - 1], r[k]
        r[k] = [a - wk * b for a, b in zip(row, prev)]
    # Back substitution.
    out = [None] * (n - 2)
    last = [v / diag[-1] for v in r[-1]]
    out[-1] = last
    for k in range(n - 4, -1, -1):
        hk, dk = hl[k + 1], diag[k]
        last = [(a - hk * b) / dk for a, b in zip(r[k], last)]
        out[k] = last
    m[1:-1] = out
    return m
