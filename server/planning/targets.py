"""Move targets in the seed's frames (3.4.1), as the tool tip's goal in the base frame.

Poses are 4x4 matrices in m; joints in rad; values already in SI (convert.py). The tool tip is
`flange @ tool_offset`; the world frame is `world_frame` in the base (settings.py). Relative
Cartesian moves add the offset along the frame's axes and turn about them
(R_goal = R(offset) @ R_now); TOOL_FRAME values are a pose in the current tool frame
(tip_goal = tip_now @ offset), for moveAbsolute and moveRelative alike.
"""
from __future__ import annotations

import enum
import math

import numpy as np

from landscape.server.errors import OutOfRange, ParamError, Unreachable
from landscape.server.device.motion_settings import MotionSettings
from landscape.robot.units import pose_matrix


# A pose value's bounds. No target of this cell lies further out: the world frame is at most
# settings.MAX_WORLD_OFFSET from the base and the arm reaches about a metre. Far beyond them,
# the arithmetic of a path (its length, its sample count) stops meaning anything.
MAX_POSITION = 1000.0          # m, each of x, y, z
MAX_ANGLE = 2.0 * math.pi      # rad, each of roll, pitch, yaw: one turn
_POSE_NAMES = ("x", "y", "z", "roll", "pitch", "yaw")


class Frame(enum.Enum):
    JOINT = "joint"
    BASE = "base"
    WORLD = "world"
    TOOL = "tool"


def check_joints(arm, joints: np.ndarray) -> np.ndarray:
    joints = np.asarray(joints, dtype=float)
    if joints.shape != (6,) or not np.all(np.isfinite(joints)):
        raise ParamError(f"a joint target needs 6 finite values, got {joints.tolist()}")
    for i, (q, lo, hi) in enumerate(zip(joints, arm.joint_min, arm.joint_max)):
        if not lo <= q <= hi:
            raise OutOfRange(f"joint {i + 1} target {q:.6g} rad is outside its range "
                             f"[{lo:.6g}, {hi:.6g}] rad", joint=str(i + 1))
    return joints


def check_pose_values(values: np.ndarray, field: str = "values") -> np.ndarray:
    """values (6,) SI, each finite and within MAX_POSITION / MAX_ANGLE; OutOfRange naming
    `field` (the request's) and the bound if not."""
    values = np.asarray(values, dtype=float)
    if values.shape != (6,) or not np.all(np.isfinite(values)):
        raise ParamError(f"a Cartesian target needs 6 finite values (x, y, z, roll, pitch, yaw), "
                         f"got {values.tolist()}", field=field)
    for i, (name, value) in enumerate(zip(_POSE_NAMES, values)):
        bound, unit = (MAX_POSITION, "m") if i < 3 else (MAX_ANGLE, "rad")
        if abs(value) > bound * (1.0 + 1e-12):    # 360 degrees in rad may round above 2 pi
            raise OutOfRange(f"{field}: {name} {value:.6g} {unit} is beyond the bound of "
                             f"{bound:.6g} {unit} either way", field=field,
                             maximum=f"{bound:.6g} {unit}")
    return values


def reach(arm) -> tuple[np.ndarray, float]:
    """The shoulder (3,), m in the base frame (J2's height on the J1 axis), and a distance
    from it (m) the flange never passes: the sum of the link lengths beyond it."""
    return (np.array([0.0, 0.0, arm.c1]),
            arm.a1 + abs(arm.b) + arm.c2 + math.hypot(arm.a2, arm.c3) + arm.c4)


def check_reach(arm, flange: np.ndarray, field: str) -> None:
    """Unreachable (OUT_OF_RANGE) naming `field` and the reach if the flange pose (4, 4) in
    the base frame, m, is beyond it: refused before anything samples the way there."""
    shoulder, furthest = reach(arm)
    distance = float(np.linalg.norm(flange[:3, 3] - shoulder))
    if not distance <= furthest:
        raise Unreachable(f"{field}: the target is not reachable: it puts the flange "
                          f"{distance:.4g} m from the arm's shoulder, and the arm reaches "
                          f"{furthest:.4g} m at most", reason_code="OUT_OF_WORKSPACE",
                          field=field, maximum=f"{furthest:.4g} m")


def goal_tip(frame: Frame, values: np.ndarray, relative: bool, tip_now: np.ndarray,
             settings: MotionSettings) -> np.ndarray:
    """The tool tip's goal in the base frame, from SI values (x, y, z m; roll, pitch, yaw rad)."""
    offset = pose_matrix(values[:3], values[3:])
    if frame is Frame.TOOL:
        return tip_now @ offset
    world = settings.world_frame if frame is Frame.WORLD else np.eye(4)
    if not relative:
        return world @ offset
    now = np.linalg.inv(world) @ tip_now
    goal = np.eye(4)
    goal[:3, :3] = offset[:3, :3] @ now[:3, :3]
    goal[:3, 3] = now[:3, 3] + offset[:3, 3]
    return world @ goal
