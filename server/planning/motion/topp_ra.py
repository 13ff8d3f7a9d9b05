"""TOPP-RA's stage solver (Pham & Pham 2018), closed form per stage, and toppra as reference.

The passes are over gridpoints of a JointPath: `topp_ra` returns the squared path speeds x at
them, `ConstAccelProfile` turns them into s(t) with a constant path acceleration per stage
(toppra's ParametrizeConstAccel), `toppra_reference` solves the same problem with the toppra
library (tests and benchmarks only: it imports toppra, ~2 s).
"""
from __future__ import annotations

import numpy as np

from .constraints import HUGE as _HUGE, tool_constraints
from .trajectory import JointPath, Limits, PlanningError

__all__ = ["topp_ra", "ConstAccelProfile", "toppra_reference"]

_A_FLOOR = 1e-9           # |dq_j/ds| below this: the joint's acceleration row ignores u
_NEWTON_STEPS = 12        # on the acceleration limit curve; the pairs take any stage left
_X_START_SLACK = 1e-9     # relative (and absolute, (rad/s)^2): a start speed this far above
                          # the controllable set is rounding, taken as its top


def topp_ra(path: JointPath, grid: np.ndarray, acceleration: np.ndarray,
            xcap: np.ndarray, rows: tuple[np.ndarray, np.ndarray, np.ndarray] | None = None,
            x_start: float = 0.0) -> np.ndarray:
    """Squared path speeds x (G,) of the time-optimal motion along `path` from the squared
    speed x_start (0: from rest) to rest.

    grid (G,): gridpoints from path_interval[0] to [1]; acceleration (6,) rad/s^2 (symmetric),
    or (G-1, 6), a row per stage (the jerk-limited timing lowers it where its samples exceed);
    xcap (G,): the velocity bounds on x (speed_caps); rows: more second-order constraints, one
    sided, per gridpoint: (ku (G, R), kx (G, R), h (R,)) with ku u + kx x <= h (the tool's
    acceleration, tool_constraints). Raises PlanningError("LIMITS") when the path cannot be
    followed (a stage with no admissible motion), or when x_start is above the first
    gridpoint's controllable set (the arm could not brake to rest by the end from it).

    Stage i (from s_i to s_{i+1}, length D) has the path acceleration u constant and
    x_{i+1} = x_i + 2 D u. Each row, at s_i or at s_{i+1} (where its x is x_i + 2 D u), bounds
    u from above (u <= beta x + w) or from below (u >= beta x + w); a joint-acceleration row
    |a_r u + b_r x| <= h_r does both, with beta_r = -b_r / a_r and w_r = +-h_r / |a_r|.
    Eliminating u: every lower line must stay below every upper line, which caps x (the
    acceleration limit curve); x_{i+1} <= K bounds x_i through the lower lines
    (x (1 + 2 D beta) <= K - 2 D w), and going forward the greatest next x is the least
    upper line's x_i + 2 D (beta x_i + w).
    """
    D = np.diff(grid)[:, None]                              # (G-1, 1)
    q1, q2 = path.evaluate(grid, (1, 2))
    a = np.concatenate([q1[:-1], q1[1:] + 2.0 * D * q2[1:]], axis=1)   # (G-1, 12)
    b = np.concatenate([q2[:-1], q2[1:]], axis=1)
    h = np.concatenate([acceleration, acceleration], axis=-1)
    # A row with a ~ 0 hardly involves u; flooring |a| keeps the algebra finite and tends to
    # the right limit: the pairs then cap x by |b x| <= h, and its lines never bind.
    a = np.where(np.abs(a) < _A_FLOOR, np.copysign(_A_FLOOR, a), a)
    inv = 1.0 / a
    beta = -b * inv
    w = h * np.abs(inv)
    lower_beta, lower_w, upper_beta, upper_w = beta, -w, beta, w
    if rows is not None:
        lower_beta, lower_w, upper_beta, upper_w = _with_rows(rows, D, beta, w)
    with np.errstate(divide="ignore", invalid="ignore", over="ignore"):
        # The acceleration limit curve: the largest x where every lower line is below every
        # upper line (capped by the velocity bounds).
        xhi = _limit_curve(lower_beta, lower_w, upper_beta, upper_w, xcap[:-1])
        # u >= -x / 2D (x_{i+1} >= 0) against each upper line.
        g = -1.0 / (2.0 * D) - upper_beta
        xhi = np.minimum(xhi, np.min(np.where(g > 0, upper_w / g, np.inf), axis=1))
        xhi = np.minimum(xhi, xcap[:-1])
        d = 1.0 + 2.0 * D * lower_beta                                    # x d <= K - 2 D w
        back_p = np.where(d > 0, 1.0 / d, 0.0)                            # x <= K p + q
        back_q = np.where(d > 0, np.minimum(-2.0 * D * lower_w * back_p, _HUGE), _HUGE)
        d = 1.0 + 2.0 * D * upper_beta                                    # x' <= d x + c
        c = np.minimum(2.0 * D * upper_w, _HUGE)
    if not np.all(xhi >= 0):
        raise PlanningError("LIMITS", "the path cannot be followed within the limits")

    # Backward pass: the controllable sets [0, K_i], K_{G-1} = 0 (at rest at the end). Each
    # stage's bound is the lower envelope of its lines in K_{i+1}; the loop visits only the
    # lines that can be on it (_binding_rows), mostly one or two, and skips stages with none.
    keep = _binding_rows(back_p, back_q, np.append(xhi[1:], 0.0), xhi)
    K = np.append(xhi, 0.0)
    K = _backward(K, keep, back_p, back_q)

    # Forward pass: from x_start, the greatest x the next controllable set admits (again an
    # envelope of lines, in x_i over [0, K_i]).
    if x_start > K[0] * (1.0 + _X_START_SLACK) + _X_START_SLACK:
        raise PlanningError("LIMITS", f"the path speed {np.sqrt(x_start):.4g} rad/s at its "
                            f"start is above the {np.sqrt(K[0]):.4g} rad/s it can brake from")
    keep = _binding_rows(d, c, K[:-1], K[1:])
    xs = _forward(K, keep, d, c, min(x_start, float(K[0])))
    xs[-1] = 0.0
    stalled = (xs[1:-1] <= 0.0)
    if stalled.any():
        raise PlanningError("LIMITS", "the path speed drops to zero at s = "
                            f"{grid[1 + int(np.argmax(stalled))]:.4g} rad")
    return xs


def _limit_curve(lower_beta: np.ndarray, lower_w: np.ndarray, upper_beta: np.ndarray,
                 upper_w: np.ndarray, cap: np.ndarray) -> np.ndarray:
    """(S,) the acceleration limit curve: the largest x at which some u lies above every lower
    line (u >= beta x + w) and below every upper line, (S, R) each -- that is, the least
    (wu - wl) / (bl - bu) over the pairs of a lower and an upper line with bl > bu -- or cap
    (S,), where that is lower.

    Newton's method on the convex f(x) = max (lower lines) - min (upper lines) from an upper
    bound: each step goes to where the two lines active at x cross, never below the root
    (the lines lie under f), and stops on it once those are the binding pair: 2-4 steps of
    O(R) instead of the R^2 pairs. Stages still moving after _NEWTON_STEPS take the pairs."""
    rows = np.arange(len(cap))
    top, bottom = np.argmax(lower_beta, axis=1), np.argmin(upper_beta, axis=1)
    # The steepest lower and the flattest upper line: one pair, so an upper bound; inf if no
    # lower line is steeper than every upper one (then they never cross for x >= 0).
    spread = lower_beta[rows, top] - upper_beta[rows, bottom]
    x = np.minimum(cap, np.where(spread > 0, (upper_w[rows, bottom] - lower_w[rows, top])
                                 / spread, np.inf))
    active = np.flatnonzero(np.isfinite(x))
    lines = (lower_beta, lower_w, upper_beta, upper_w)
    for _ in range(_NEWTON_STEPS):
        if not active.size:
            return x
        # While most stages still move, work on the whole arrays rather than gather them.
        whole = 2 * len(active) > len(x)
        bl, wl, bu, wu = lines if whole else (a[active] for a in lines)
        at = np.where(np.isfinite(x), x, 0.0)[:, None] if whole else x[active, None]
        here = np.arange(len(at))
        r = np.argmax(bl * at + wl, axis=1)          # the highest lower line at x
        q = np.argmin(bu * at + wu, axis=1)          # the lowest upper line at x
        gap = bl[here, r] - bu[here, q]
        cross = (wu[here, q] - wl[here, r]) / gap
        if whole:
            cross = cross[active]
            gap = gap[active]
        moving = (gap > 0) & (cross < x[active])
        x[active[moving]] = cross[moving]
        active = active[moving]
    if active.size:
        bl, wl, bu, wu = (a[active] for a in (lower_beta, lower_w, upper_beta, upper_w))
        gap = bl[:, :, None] - bu[:, None, :]
        pairs = np.where(gap > 0, (wu[:, None, :] - wl[:, :, None]) / gap, np.inf)
        x[active] = np.minimum(x[active], pairs.min(axis=(1, 2)))
    return x


def _with_rows(rows, D: np.ndarray, beta: np.ndarray, w: np.ndarray):
    """The joint rows' lines (beta, +-w, (S, 12)) with the one-sided rows' added: (lower beta,
    lower w, upper beta, upper w), (S, 12 + 2R) each. A one-sided row sets only one of its two
    lines; the other is a flat line out of reach (-+_HUGE), so it never binds."""
    ku, kx, h = rows
    # At both ends of each stage; at the end x_{i+1} = x_i + 2 D u.
    cu = np.concatenate([ku[:-1], ku[1:] + 2.0 * D * kx[1:]], axis=1)    # (S, 2R)
    cx = np.concatenate([kx[:-1], kx[1:]], axis=1)
    bound = np.concatenate([h, h])
    cu = np.where(np.abs(cu) < _A_FLOOR, np.copysign(_A_FLOOR, cu), cu)
    new_beta, offset = -cx / cu, bound / cu
    up = cu > 0
    return (np.concatenate([beta, np.where(up, 0.0, new_beta)], axis=1),
            np.concatenate([-w, np.where(up, -_HUGE, offset)], axis=1),
            np.concatenate([beta, np.where(up, new_beta, 0.0)], axis=1),
            np.concatenate([w, np.where(up, offset, _HUGE)], axis=1))


def _binding_rows(slope: np.ndarray, intercept: np.ndarray, upper: np.ndarray,
                  cap: np.ndarray) -> np.ndarray:
    """(S, R) bool: the lines y = slope * z + intercept (S stages, R rows) that can be the least
    one, and below the stage's cap (S,), for some z in [0, upper] (S,).

    Exact pruning: with a the least line at z = 0 and b the least at z = upper, min(a, b) is
    concave, so a line at or above it where a and b cross is at or above it everywhere on
    the interval; only a, b and lines below that point can matter."""
    upper = upper[:, None]
    at0, at1 = intercept, slope * upper + intercept
    rows = np.arange(slope.shape[0])
    a, b = np.argmin(at0, axis=1), np.argmin(at1, axis=1)
    pa, qa, pb, qb = slope[rows, a], intercept[rows, a], slope[rows, b], intercept[rows, b]
    with np.errstate(divide="ignore", invalid="ignore"):
        cross = np.clip((qb - qa) / (pa - pb), 0.0, upper[:, 0])
    cross = np.where(np.isfinite(cross), cross, 0.0)[:, None]
    below = slope * cross + intercept < (pa * cross[:, 0] + qa)[:, None]
    keep = below
    keep[rows, a] = True
    keep[rows, b] = True
    return keep & ((at0 < cap[:, None]) | (at1 < cap[:, None]))


def _backward(K: np.ndarray, keep: np.ndarray, p: np.ndarray, q: np.ndarray) -> np.ndarray:
    """K_i = min(K_i, min over kept rows r of stage i: K_{i+1} p_r + q_r), from the end back;
    K (G,) holds the caps on entry. One flat loop over the kept rows, last stage first (a
    stage's rows are consecutive, so K_{i+1} is final when stage i's rows come)."""
    stage = np.nonzero(keep)[0][::-1].tolist()
    P, Q = p[keep][::-1].tolist(), q[keep][::-1].tolist()
    Kl = K.tolist()
    for i, pr, qr in zip(stage, P, Q):
        bound = Kl[i + 1] * pr + qr
        if bound < Kl[i]:
            Kl[i] = bound if bound > 0.0 else 0.0
    return np.array(Kl)


def _forward(K: np.ndarray, keep: np.ndarray, d: np.ndarray, c: np.ndarray,
             x_start: float) -> np.ndarray:
    """x_0 = x_start, x_{i+1} = min(K_{i+1}, min over kept rows r of stage i: d_r x_i + c_r), one
    flat loop over the kept rows, first stage first."""
    stage = np.nonzero(keep)[0].tolist()
    Dl, Cl = d[keep].tolist(), c[keep].tolist()
    xs = K.tolist()
    xs[0] = x_start
    for i, dr, cr in zip(stage, Dl, Cl):
        bound = dr * xs[i] + cr
        if bound < xs[i + 1]:
            xs[i + 1] = bound if bound > 0.0 else 0.0
    return np.array(xs)


class ConstAccelProfile:
    """s(t) from squared path speeds x (G,) at gridpoints (G,): constant path acceleration
    u_i = (x_{i+1} - x_i) / (2 (s_{i+1} - s_i)) on each stage (toppra's ParametrizeConstAccel),
    vectorised. times (G,) s: when each gridpoint is reached."""

    def __init__(self, grid: np.ndarray, xs: np.ndarray):
        self.grid = grid
        self.sd = np.sqrt(np.maximum(xs, 0.0))
        D = np.diff(grid)
        self.u = np.diff(xs) / (2.0 * D)
        with np.errstate(divide="ignore"):
            dt = 2.0 * D / (self.sd[:-1] + self.sd[1:])
        if not np.all(np.isfinite(dt)):
            raise PlanningError("LIMITS", "the path speed is zero on a stage")
        self.times = np.concatenate([[0.0], np.cumsum(dt)])

    @property
    def duration(self) -> float:
        return float(self.times[-1])

    def sample(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Path position s (K,) rad and speed ds/dt (K,) rad/s at times t (K,) s."""
        i = np.clip(np.searchsorted(self.times, t, side="right") - 1, 0, len(self.u) - 1)
        r = np.maximum(t - self.times[i], 0.0)
        sd0, u = self.sd[i], self.u[i]
        sd = np.maximum(sd0 + u * r, 0.0)
        s = np.clip(self.grid[i] + r * (sd0 + 0.5 * u * r), self.grid[i], self.grid[i + 1])
        return s, sd


def toppra_reference(path: JointPath, grid: np.ndarray, limits: Limits, tool_path=None
                     ) -> np.ndarray:
    """The same problem solved by the toppra library (seidel LP solver, interpolation scheme):
    squared path speeds (G,). For tests and benchmarks; imports toppra (slow, ~2 s cold)."""
    import toppra
    import toppra.algorithm
    import toppra.constraint

    class SpeedCaps(toppra.constraint.LinearConstraint):
        """Our velocity bounds on x (joint and tool speeds) as a toppra first-order constraint."""

        def __init__(self):
            super().__init__()
            self.dof = 6

        def compute_constraint_params(self, path_, grid_, *args, **kwargs):
            caps = tool_constraints(path_, grid_, limits, tool_path)[0]
            return (None, None, None, None, None, None,
                    np.stack([np.zeros_like(caps), caps], axis=1))

    class ToolRows(toppra.constraint.LinearConstraint):
        """tool_constraints' one-sided rows: ku u + kx x <= h at each gridpoint."""

        def __init__(self):
            super().__init__()
            self.dof = 6
            self.identical = True
            self.discretization_type = interpolation

        def compute_constraint_params(self, path_, grid_, *args, **kwargs):
            ku, kx, h = tool_constraints(path_, grid_, limits, tool_path)[1]
            # A LinearConstraint discretises itself (as JointAccelerationConstraint does).
            return toppra.constraint.canlinear_colloc_to_interpolate(
                ku, kx, np.zeros_like(ku), np.eye(len(h)), h, None, None, grid_, identical=True)

    interpolation = toppra.constraint.DiscretizationType.Interpolation
    acc = toppra.constraint.JointAccelerationConstraint(limits.acceleration,
                                                        discretization_scheme=interpolation)
    constraints = [SpeedCaps(), acc]
    if tool_constraints(path, grid[:2], limits, tool_path)[1] is not None:
        constraints.append(ToolRows())
    algo = toppra.algorithm.TOPPRA(constraints, path, gridpoints=grid, solver_wrapper="seidel")
    _, sd, _ = algo.compute_parameterization(0.0, 0.0)[:3]
    if sd is None:
        raise PlanningError("LIMITS", "toppra found no parametrization")
    return np.asarray(sd) ** 2
