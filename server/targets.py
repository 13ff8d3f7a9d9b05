"""Move targets in the seed's frames (3.4.1), as the tool tip's goal in the base frame.

Poses are 4x4 matrices in m; joints in rad; values already in SI (convert.py). The tool tip is
`flange @ tool_offset`; the world frame is `world_frame` in the base (settings.py). Relative
Cartesian moves add the offset along the frame's axes and turn about them
(R_goal = R(offset) @ R_now); TOOL_FRAME values are a pose in the current tool frame
(tip_goal = tip_now @ offset), for moveAbsolute and moveRelative alike.
"""
from __future__ import annotations

import enum

import numpy as np

from landscape.server.errors import OutOfRange, ParamError
from landscape.server.settings import MotionSettings
from landscape.server.units import pose_matrix


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


def check_pose_values(values: np.ndarray) -> np.ndarray:
    values = np.asarray(values, dtype=float)
    if values.shape != (6,) or not np.all(np.isfinite(values)):
        raise ParamError(f"a Cartesian target needs 6 finite values (x, y, z, roll, pitch, yaw), "
                         f"got {values.tolist()}")
    return values


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
