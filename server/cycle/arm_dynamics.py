"""The arm's inverse dynamics with what its flange carries, in pinocchio: the joint torques the
arm model says a motion needs (gravity, inertia, Coriolis and centrifugal terms).

The cycle (executor.py) runs `ArmDynamics.torques` every cycle: pinocchio's recursive
Newton-Euler algorithm (RNEA) at the measured position and velocity and the commanded
acceleration. The ring carries the result beside the measured torques (feedback.MODEL_TAU);
their difference is the external load (a contact, a payload the model does not know of).

The payload is what the server says the flange carries (tooling.py: a tool coupled or
released, a part taken or let go), as pinocchio's ten dynamic parameters in the flange frame:
mass (kg), mass times centre of mass (kg*m), inertia about the flange origin (kg*m^2; xx, xy,
yy, xz, yz, zz). Parameters add up: a tool's plus its part's are the payload. `tool_payload`
and `part_payload` compute them from the cell file (the tool's URDF, the part's box), on the
server; nothing here reads the simulator.

Units: rad, rad/s, rad/s^2, N*m; gravity in m/s^2 in the arm's base frame.
"""
from __future__ import annotations

import numpy as np
import pinocchio as pin

from landscape.robot.arm import ArmModel
from landscape.robot.cell import BoxSpec, Cell, ToolSpec
from landscape.robot.pinocchio_model import PinocchioModel
from landscape.robot.tool_shapes import tool_urdf

NO_PAYLOAD = (0.0,) * 10


def base_gravity(cell: Cell) -> np.ndarray:
    """The cell's gravity (3,) in the arm's base frame (m/s^2)."""
    from landscape.robot.units import pose_matrix
    return pose_matrix(cell.base.xyz, cell.base.rpy)[:3, :3].T @ np.asarray(cell.world.gravity)


class ArmDynamics:
    """The arm model's inverse dynamics. Not thread-safe (one pinocchio Data)."""

    def __init__(self, arm: ArmModel, gravity=(0.0, 0.0, -9.81)):
        base = PinocchioModel(arm)
        self.model = base.model
        self.model.gravity = pin.Motion(np.asarray(gravity, dtype=float), np.zeros(3))
        self.data = self.model.createData()
        flange = self.model.frames[base.flange]
        self._joint, self._flange = flange.parentJoint, flange.placement
        self._bare = self.model.inertias[self._joint].copy()
        self.payload = NO_PAYLOAD

    def set_payload(self, parameters) -> None:
        """The flange carries `parameters` (10,) (module docstring); NO_PAYLOAD: nothing."""
        self.payload = tuple(float(p) for p in parameters)
        inertia = self._bare
        if self.payload[0] > 0:   # (no mass: no centre of mass either)
            load = pin.Inertia.FromDynamicParameters(np.array(self.payload))
            inertia = inertia + self._flange.act(load)
        self.model.inertias[self._joint] = inertia

    def torques(self, q: np.ndarray, v: np.ndarray, a: np.ndarray) -> np.ndarray:
        """(6,) N*m: what moving through q with velocity v and acceleration a takes."""
        return pin.rnea(self.model, self.data, q, v, a)


def tool_payload(spec: ToolSpec) -> np.ndarray:
    """A tool's dynamic parameters (10,) in its plate frame, the flange's when it is mounted:
    its URDF's links together (a gripper's fingers open)."""
    model = pin.buildModelFromXML(tool_urdf(spec))
    data = model.createData()
    q = np.full(model.nq, spec.stroke / 2)   # finger joints: half the gap, open
    pin.forwardKinematics(model, data, q)
    whole = pin.Inertia.Zero()
    for joint in range(model.njoints):   # joint 0 (the universe) carries the plate's link
        whole += data.oMi[joint].act(model.inertias[joint])
    return whole.toDynamicParameters()


def part_payload(box: BoxSpec, in_flange: np.ndarray) -> np.ndarray:
    """A box part's dynamic parameters (10,) in the flange frame, its centre at `in_flange`
    (4, 4)."""
    inertia = pin.Inertia.FromBox(box.mass, *box.size)
    placement = pin.SE3(np.asarray(in_flange[:3, :3]), np.asarray(in_flange[:3, 3]))
    return placement.act(inertia).toDynamicParameters()
