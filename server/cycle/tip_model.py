"""The arm seen from its tool tip, in pinocchio: pose, Jacobian and wrench at the tip.

Used every cycle by the loops of the cycle process (jog integration, the compliance loop) and
by the server to express the flange's force/torque sensor at the tool. pinocchio is the one
source of rotation and spatial algebra here (SE3, Force, log3), not hand-written copies.

Frames: base_link (the arm's base), flange (URDF tool0), tip = flange @ tool_offset (4x4, m).
Units: rad, m, N, N*m; joint vectors (6,), joint 1 first.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin

from landscape.robot.arm import ArmModel
from landscape.robot.pinocchio_model import PinocchioModel


def wrench_at_tip(wrench: np.ndarray, tool_offset: np.ndarray) -> np.ndarray:
    """A flange wrench (6,): force (N) and torque about the flange origin (N*m), in the flange
    frame, as the same wrench in the tip frame, torque about the tip."""
    tip = pin.SE3(tool_offset[:3, :3], tool_offset[:3, 3])
    return tip.actInv(pin.Force(wrench[:3], wrench[3:])).vector


def wrench_map(tool_offset: np.ndarray) -> np.ndarray:
    """(6, 6): wrench_at_tip as a matrix, for loops that apply it every cycle."""
    return np.column_stack([wrench_at_tip(e, tool_offset) for e in np.eye(6)])


class TipModel:
    """The arm's kinematics at its tool tip. Not thread-safe (one pinocchio Data)."""

    def __init__(self, arm: ArmModel):
        base = PinocchioModel(arm)
        self.model, self.data = base.model, base.model.createData()
        flange = self.model.frames[base.flange]
        self.tip = self.model.addFrame(pin.Frame("tip", flange.parentJoint, base.flange,
                                                 flange.placement, pin.FrameType.OP_FRAME))
        self.data = self.model.createData()
        self._flange_placement = flange.placement.copy()
        self.tool_offset: np.ndarray | None = None
        self.set_tool(np.eye(4))

    def set_tool(self, tool_offset: np.ndarray) -> None:
        """The tip is `tool_offset` (4x4, m) in the flange frame (the same array again costs
        nothing: loops call this every cycle)."""
        if tool_offset is self.tool_offset:
            return
        self.tool_offset = tool_offset
        offset = pin.SE3(np.asarray(tool_offset[:3, :3], dtype=float),
                         np.asarray(tool_offset[:3, 3], dtype=float))
        self.model.frames[self.tip].placement = self._flange_placement * offset

    def forward(self, q: np.ndarray) -> np.ndarray:
        """The tip pose (4, 4) in base_link."""
        pin.framesForwardKinematics(self.model, self.data, q)
        return self.data.oMf[self.tip].homogeneous

    def jacobian(self, q: np.ndarray) -> np.ndarray:
        """(6, 6): the tip's linear (m/rad) and angular (rad/rad) velocity per joint, in
        base_link axes, at the tip (pinocchio's LOCAL_WORLD_ALIGNED). The tip's pose at q is
        `last_pose` afterwards."""
        return pin.computeFrameJacobian(self.model, self.data, q, self.tip,
                                        pin.LOCAL_WORLD_ALIGNED)

    @property
    def last_pose(self) -> np.ndarray:
        """The tip (4, 4) at the q of the last forward() or jacobian()."""
        return self.data.oMf[self.tip].homogeneous

    def pose_error(self, target: np.ndarray, q: np.ndarray | None = None) -> np.ndarray:
        """(6,): how far the tip at q (None: at the last forward or jacobian) is from `target`
        (4x4): position (m) and rotation vector (rad), in base_link axes; zero when there."""
        now = self.forward(q) if q is not None else self.last_pose
        rotation = pin.log3(target[:3, :3] @ now[:3, :3].T)
        return np.concatenate([target[:3, 3] - now[:3, 3], rotation])


def damped_solve(jacobian: np.ndarray, twist: np.ndarray, damping: float = 1e-4) -> np.ndarray:
    """Joint motion (6,) giving the tip motion `twist` (6,), damped near singularities:
    J^T (J J^T + damping^2 I)^-1 twist (damped least squares)."""
    jjt = jacobian @ jacobian.T
    jjt[np.diag_indices(6)] += damping * damping
    return jacobian.T @ np.linalg.solve(jjt, twist)
