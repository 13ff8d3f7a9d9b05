"""Cartesian paths as dense joint paths: straight lines and arcs of the tool tip, solved by the
closed-form inverse kinematics sample by sample, in one configuration, joints continuous.

Poses are (4, 4) homogeneous matrices in base_link, metres. The tool tip is flange @ tcp, tcp
(4, 4) the tool offset (flange -> tip, identity by default): straight_line and arc move the TIP
on the line or circle, and take goals as tip poses. Joint paths are (K, 6) rad, row 0 the
start q_start exactly. Every sample solves the pose exactly (closed form); between samples the
timed path follows the joint spline through them, which leaves the line by micrometres at the
default steps (bench/bench_planning.py measures it).

A line or arc needing more than MAX_SAMPLES samples raises PlanningError("TOO_MANY_SAMPLES")
before any sample is made. Other failures raise PlanningError before anything moves, with
`fraction` (0..1 along the segment)
at the first sample that fails: OUT_OF_WORKSPACE (no solution at all), CONFIGURATION_CHANGE
(solutions, but not in q_start's shoulder/elbow/wrist configuration), OUT_OF_JNT_RANGE (the
continuous joint motion leaves a joint's range: J4/J6 are never allowed a 2*pi jump), and
SINGULARITY (|sin q5| below `WRIST_SINGULAR`, or a joint turning more than `max_joint_step`
between two samples: the joint speed blowing up near a singularity).
"""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin

from landscape.robot.kinematics import (BRANCHES, Config, Kinematics, PosNeg, ReversingResult,
                                      Shoulder, wrap_angle)

from .trajectory import PlanningError

__all__ = ["tool_pose", "straight_line", "arc", "circle", "straight_path", "joint_waypoints",
           "slerp", "WRIST_SINGULAR", "MAX_SAMPLES"]

WRIST_SINGULAR = 1e-3     # |sin q5| below this: the wrist is (too near) singular
# Samples of one line or arc, counted before any is made: a bound on memory (a few hundred
# bytes each) and time. Any path within the arm's reach needs a few thousand at most.
MAX_SAMPLES = 100_000
_TWO_PI = 2.0 * math.pi
_BOUNDARY_SAMPLES = 2     # a blow-up this close before a workspace failure is that failure


def tool_pose(kin: Kinematics, tcp=None):
    """The tool path function for timing.time_path: q (..., 6) -> tip poses (..., 4, 4)."""
    if tcp is None:
        return kin.forward
    T = _pose(tcp, "tcp")
    return lambda q: kin.forward(q) @ T


def straight_line(kin: Kinematics, q_start, goal, *, tcp=None, max_step: float = 0.005,
                  max_angle_step: float = 0.02, max_joint_step: float = 0.1) -> np.ndarray:
    """Dense joint path (K, 6) whose tool tip moves on the straight line from its pose at
    q_start to `goal` (tip pose, (4, 4)), the orientation turning on the shortest rotation
    (slerp), in q_start's configuration, joints continuous. Samples are evenly spaced, at most
    max_step (m) and max_angle_step (rad) apart; max_joint_step (rad) is the largest joint step
    between samples at those spacings (smaller spacings scale it down). K = 1 if the goal is
    the start."""
    q0 = _joints(kin, q_start)
    T_tcp = np.eye(4) if tcp is None else _pose(tcp, "tcp")
    start = kin.forward(q0) @ T_tcp
    goal = _pose(goal, "goal")
    distance = float(np.linalg.norm(goal[:3, 3] - start[:3, 3]))
    angle = _angle(start[:3, :3], goal[:3, :3])
    n = _intervals(distance, angle, max_step, max_angle_step)
    f = np.linspace(0.0, 1.0, n + 1)
    tips = np.empty((n + 1, 4, 4))
    tips[:] = np.eye(4)
    tips[:, :3, :3] = slerp(start[:3, :3], goal[:3, :3], f)
    tips[:, :3, 3] = start[:3, 3] + f[:, None] * (goal[:3, 3] - start[:3, 3])
    step = max(distance / max_step, angle / max_angle_step) / n if n else 0.0
    return _follow(kin, q0, tips, T_tcp, f, max_joint_step * min(1.0, max(step, 0.1)))


def arc(kin: Kinematics, q_start, via, goal, *, tcp=None, max_step: float = 0.005,
        max_angle_step: float = 0.02, max_joint_step: float = 0.1) -> np.ndarray:
    """Dense joint path (K, 6) whose tool tip moves on the circle through its start position,
    via's and goal's positions (tip poses (4, 4)), from the start through via to goal; the
    orientation turns from the start's to goal's by slerp, in proportion to the angle swept
    (via's orientation is not used). Steps and failures as straight_line; three points on one
    line (or two coinciding) raise PlanningError("DEGENERATE")."""
    q0 = _joints(kin, q_start)
    T_tcp = np.eye(4) if tcp is None else _pose(tcp, "tcp")
    start = kin.forward(q0) @ T_tcp
    via, goal = _pose(via, "via"), _pose(goal, "goal")
    centre, radius, u, w, sweep = circle(start[:3, 3], via[:3, 3], goal[:3, 3])
    angle = _angle(start[:3, :3], goal[:3, :3])
    # Chord steps of max_step along the arc, and a few degrees of sweep at most, so that the
    # spline between samples stays close to the circle even on small radii.
    n = _intervals(radius * sweep, angle, max_step, max_angle_step, least=sweep / 0.1)
    f = np.linspace(0.0, 1.0, n + 1)
    phi = f * sweep
    tips = np.empty((n + 1, 4, 4))
    tips[:] = np.eye(4)
    tips[:, :3, :3] = slerp(start[:3, :3], goal[:3, :3], f)
    tips[:, :3, 3] = centre + radius * (np.cos(phi)[:, None] * u + np.sin(phi)[:, None] * w)
    tips[-1, :3, 3] = goal[:3, 3]        # exactly, not within rounding of the circle
    step = max(radius * sweep / max_step, angle / max_angle_step) / n
    return _follow(kin, q0, tips, T_tcp, f, max_joint_step * min(1.0, max(step, 0.1)))


def circle(p0, p1, p2) -> tuple[np.ndarray, float, np.ndarray, np.ndarray, float]:
    """The circle through three points (3,), m, met in the order p0, p1, p2: (centre (3,),
    radius, u, w, sweep) with u, w (3,) orthonormal in its plane, u towards p0, so that the
    points are centre + radius (cos phi u + sin phi w), phi from 0 to sweep (rad, (0, 2 pi)).
    Raises PlanningError("DEGENERATE") for collinear or coinciding points."""
    p0, p1, p2 = (np.asarray(p, dtype=float) for p in (p0, p1, p2))
    a, b = p1 - p0, p2 - p0
    n = np.cross(a, b)
    size = max(np.linalg.norm(a), np.linalg.norm(b), np.linalg.norm(p2 - p1))
    if size < 1e-9 or np.linalg.norm(n) <= 1e-9 * size * size:
        raise PlanningError("DEGENERATE", "the arc's start, via and goal positions are collinear "
                            "or coincide", fraction=0.0)
    nn = float(n @ n)
    centre = p0 + np.cross(float(a @ a) * b - float(b @ b) * a, n) / (2.0 * nn)
    radius = float(np.linalg.norm(p0 - centre))
    u = (p0 - centre) / radius
    w = np.cross(n / math.sqrt(nn), u)
    # With the normal a x b the points come counter-clockwise: p1 before p2.
    r2 = p2 - centre
    sweep = math.atan2(float(r2 @ w), float(r2 @ u)) % _TWO_PI
    return centre, radius, u, w, sweep


def straight_path(kin: Kinematics, q_start, goals, *, tcp=None, **steps
                  ) -> tuple[np.ndarray, tuple[int, ...]]:
    """Straight lines through tip poses goals (M, 4, 4), from the tip's pose at q_start: the
    joint path (K, 6) and the row of each goal in it (M,), for time_path's marks. A failure
    on the line to goals[i] raises PlanningError with index=i and the fraction along that
    line. steps: straight_line's max_step, max_angle_step, max_joint_step."""
    goals = np.asarray(goals, dtype=float)
    if goals.ndim != 3 or goals.shape[1:] != (4, 4):
        raise ValueError(f"goals must have shape (M, 4, 4), got {goals.shape}")
    parts, rows = [_joints(kin, q_start)[None]], []
    for i, goal in enumerate(goals):
        try:
            line = straight_line(kin, parts[-1][-1], goal, tcp=tcp, **steps)
        except PlanningError as err:
            raise err.at_index(i) from None
        parts.append(line[1:])
        rows.append(sum(len(p) for p in parts) - 1)
    return np.concatenate(parts), tuple(rows)


def joint_waypoints(kin: Kinematics, poses, q_start, *, tcp=None,
                    config: Config = Config()) -> np.ndarray:
    """Joint waypoints (M, 6) for tip poses (M, 4, 4) of a joint-interpolated move: each the
    solution in `config` (default any) closest to the one before (q_start for the first),
    J4/J6 taken among their 2*pi equivalents in range. An unreachable pose i raises
    PlanningError(reason, index=i) with OUT_OF_WORKSPACE, OUT_OF_JNT_RANGE or
    CONFIGURATION_CHANGE (the LLI reversing results)."""
    poses = np.asarray(poses, dtype=float)
    if poses.ndim != 3 or poses.shape[1:] != (4, 4):
        raise ValueError(f"poses must have shape (M, 4, 4), got {poses.shape}")
    inv_tcp = np.eye(4) if tcp is None else np.linalg.inv(_pose(tcp, "tcp"))
    reasons = {ReversingResult.OUT_OF_WORKSPACE: "OUT_OF_WORKSPACE",
               ReversingResult.OUT_OF_JNT_RANGE: "OUT_OF_JNT_RANGE",
               ReversingResult.INVALID_CONFIG: "CONFIGURATION_CHANGE",
               ReversingResult.INVALID_ORIENTATION: "DEGENERATE"}
    out, near = [], _joints(kin, q_start)
    for i, pose in enumerate(poses):
        q, result = kin.reverse(pose @ inv_tcp, near, config)
        if q is None:
            raise PlanningError(reasons.get(result, "OUT_OF_WORKSPACE"),
                                f"no joint solution ({result.name})", index=i)
        out.append(q)
        near = q
    return np.array(out).reshape(len(poses), 6)


def slerp(R0: np.ndarray, R1: np.ndarray, f: np.ndarray) -> np.ndarray:
    """Rotations (K, 3, 3) on the shortest rotation from R0 to R1 (3, 3) at fractions f (K,):
    R0 @ exp(f * log(R0^T R1))."""
    w = pin.log3(R0.T @ R1)
    angle = float(np.linalg.norm(w))
    axis = w / angle if angle > 0.0 else np.array([0.0, 0.0, 1.0])
    t = np.asarray(f, dtype=float)[:, None, None] * angle
    K = pin.skew(axis)
    # Rodrigues, exp(t K) = I + sin t K + (1 - cos t) K^2, for every sample in one numpy
    # expression: pinocchio's exp3 takes one rotation a call.
    steps = np.eye(3) + np.sin(t) * K + (1.0 - np.cos(t)) * (K @ K)
    return R0 @ steps


# ---- helpers ---------------------------------------------------------------------------------

def _follow(kin: Kinematics, q0: np.ndarray, tips: np.ndarray, T_tcp: np.ndarray,
            fraction: np.ndarray, joint_step: float) -> np.ndarray:
    """Joints (K, 6) reaching tip poses (K, 4, 4) in q0's configuration, continuous from q0."""
    flanges = tips @ np.linalg.inv(T_tcp)
    solutions = kin.solve_batch(flanges, q0)                  # (K, 8, 6), NaN where none
    cfg = kin.configuration(q0)
    q = solutions[:, BRANCHES.index(cfg), :]
    workspace = np.isnan(solutions[..., 0]).all(axis=1)       # no branch at all
    # Continuity: each sample's joints among their 2*pi equivalents, closest to the sample
    # before (accumulated from q0, then snapped onto the exact IK value plus whole turns).
    ok = ~np.isnan(q[:, 0])
    first_bad = int(np.argmin(ok)) if not ok.all() else len(q)
    good = q[:first_bad]
    steps = wrap_angle(np.diff(np.vstack([q0, good]), axis=0))
    approx = q0 + np.cumsum(steps, axis=0)
    good = good + _TWO_PI * np.round((approx - good) / _TWO_PI)
    if len(good):
        good[0] = q0
    jump = np.max(np.abs(np.diff(good, axis=0)), axis=1) if len(good) > 1 else np.zeros(0)
    singular = np.concatenate([[False], jump > joint_step]) | \
        (np.abs(np.sin(good[:, 4])) < WRIST_SINGULAR)
    singular[0] = False                                       # starting there is allowed
    lower, upper = kin.arm.lower - 1e-9, kin.arm.upper + 1e-9
    out_of_range = np.any((good < lower) | (good > upper), axis=1)

    failures = []   # (sample, reason, message)
    if first_bad < len(q):
        # As LLI reverseKin ranks it: another configuration in range, or none at all.
        other = kin.reverse(flanges[first_bad], good[-1] if len(good) else q0)[0] is not None
        if other:
            failures.append((first_bad, "CONFIGURATION_CHANGE",
                             f"the path needs another configuration than {_label(cfg)}"))
        else:
            failures.append((first_bad, "OUT_OF_WORKSPACE" if workspace[first_bad] else
                             "OUT_OF_JNT_RANGE", "the path leaves the workspace"
                             if workspace[first_bad] else "the path leaves the joint ranges"))
    if out_of_range.any():
        k = int(np.argmax(out_of_range))
        joints = np.flatnonzero((good[k] < lower) | (good[k] > upper)) + 1
        failures.append((k, "OUT_OF_JNT_RANGE", f"joint(s) {joints.tolist()} out of range"))
    if singular.any():
        k = int(np.argmax(singular))
        # Nearing the workspace boundary the arm stretches (q3 -> 0): that is the boundary.
        if not (first_bad < len(q) and first_bad - k <= _BOUNDARY_SAMPLES):
            failures.append((k, "SINGULARITY", "the path passes too near a singularity "
                             "(joint speed blow-up)" if k and jump[k - 1] > joint_step else
                             "the path passes through the wrist singularity (q5 = 0)"))
    if failures:
        k, reason, message = min(failures, key=lambda item: item[0])
        raise PlanningError(reason, message, fraction=float(fraction[k]))
    return good


def _label(cfg: Config) -> str:
    return "/".join(x.name.lower() for x in (Shoulder(cfg.shoulder), PosNeg(cfg.elbow),
                                             PosNeg(cfg.wrist)))


def _intervals(distance: float, angle: float, max_step: float, max_angle_step: float,
               least: float = 0.0) -> int:
    """Sample intervals (at least `least`) for steps of at most max_step (m) and max_angle_step
    (rad); PlanningError("TOO_MANY_SAMPLES") past MAX_SAMPLES, counted in floating point."""
    if not (max_step > 0 and max_angle_step > 0):
        raise ValueError("max_step and max_angle_step must be positive")
    n = max(distance / max_step - 1e-9, angle / max_angle_step - 1e-9, least, 0.0)
    if not n < MAX_SAMPLES:      # NaN and infinity too
        raise PlanningError("TOO_MANY_SAMPLES", f"the path is {distance:.4g} m long and turns "
                            f"{angle:.4g} rad: it needs more than {MAX_SAMPLES} samples",
                            fraction=0.0)
    return math.ceil(n)


def _angle(Ra: np.ndarray, Rb: np.ndarray) -> float:
    """Angle (rad) of the rotation turning Ra into Rb."""
    return float(np.linalg.norm(pin.log3(Ra.T @ Rb)))


def _joints(kin: Kinematics, q) -> np.ndarray:
    q = np.asarray(q, dtype=float)
    if q.shape != (6,) or not np.all(np.isfinite(q)):
        raise ValueError(f"joints must be 6 finite values (rad), got {q!r}")
    return q


def _pose(T, name: str) -> np.ndarray:
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise ValueError(f"{name} must be a finite (4, 4) pose")
    return T
