"""The TX90-class arm in pinocchio, built from the generated URDF (sim/arm.py): a cross-check of
the closed form (kinematics.py), the flange Jacobian, and a damped-least-squares IK to compare
it with. pinocchio is imported when the class is first used (a heavy import).

Units and shapes as in kinematics.py: poses (4, 4) of the flange (tool0) in base_link, metres;
joint vectors (6,) in radians.
"""
from __future__ import annotations

import numpy as np

from landscape.robot.arm import ArmModel, urdf

__all__ = ["PinocchioModel"]


class PinocchioModel:
    """The same arm in pinocchio, built from `urdf(arm)`: cross-checks, Jacobian, numeric IK.

    The joint vector q (6,) is pinocchio's configuration (all joints revolute, nq = 6).
    """

    def __init__(self, arm: ArmModel):
        import pinocchio as pin   # heavy; only the users of this class pay for it

        self._pin = pin
        self.model = pin.buildModelFromXML(urdf(arm))
        self.data = self.model.createData()
        self.flange = self.model.getFrameId("tool0")

    def forward(self, q) -> np.ndarray:
        """Flange (tool0) pose in base_link, (4, 4)."""
        self._pin.framesForwardKinematics(self.model, self.data, np.asarray(q, dtype=float))
        return self.data.oMf[self.flange].homogeneous.copy()

    def jacobian(self, q) -> np.ndarray:
        """(6, 6) flange Jacobian, world-aligned at the flange origin: rows (vx, vy, vz) in m/rad
        then (wx, wy, wz) in rad/rad, expressed in base_link axes; columns joints 1..6."""
        pin = self._pin
        return pin.computeFrameJacobian(self.model, self.data, np.asarray(q, dtype=float),
                                        self.flange, pin.LOCAL_WORLD_ALIGNED).copy()

    def ik_dls(self, pose, q0, tol: float = 1e-10, max_iter: int = 1000, step: float = 1.0,
               damping: float = 1e-12) -> tuple[np.ndarray, bool, int]:
        """Closed-loop damped-least-squares IK (pinocchio's documented CLIK scheme) for the flange.

        Iterates q <- q + step * J^T (J J^T + damping I)^-1 e, with e = log6(oMf^-1 oMdes) the
        flange error in its own frame and J its Jacobian, until |e| < tol. Joint ranges are
        not enforced. Returns (q (6,), converged, iterations).
        """
        pin = self._pin
        model, data, fid = self.model, self.data, self.flange
        pose = np.asarray(pose, dtype=float)
        target = pin.SE3(pose[:3, :3], pose[:3, 3])
        q = np.array(q0, dtype=float)
        eye = np.eye(6)
        for it in range(max_iter):
            pin.computeJointJacobians(model, data, q)   # also runs forward kinematics
            pin.updateFramePlacement(model, data, fid)
            error_pose = data.oMf[fid].actInv(target)
            e = pin.log6(error_pose).vector
            if np.linalg.norm(e) < tol:
                return q, True, it
            J = pin.Jlog6(error_pose.inverse()) @ pin.getFrameJacobian(model, data, fid, pin.LOCAL)
            v = J.T @ np.linalg.solve(J @ J.T + damping * eye, e)
            q = pin.integrate(model, q, step * v)
        return q, False, max_iter
