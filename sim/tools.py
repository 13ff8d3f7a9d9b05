"""The tools of the cell as pybullet bodies, and their mechanics: a parallel gripper and a cup.

A tool's frame is its mounting plate (z along the tool axis, away from the flange; the tip is
`length` along z). Each tool is a URDF (simple shapes) loaded into the world's physics client.
Holding a part is a fixed constraint at the part's present pose relative to the tool, with the
part's collisions against the tool switched off: a supervisory-control simulator, not a grasp
study. Only the mounted tool acts on its outputs (air and signals pass through the changer).

Frames are (position (3,), quaternion xyzw (4,)) pairs in the world, as pybullet uses them.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin
import pybullet as pb

from landscape.robot.cell import ToolSpec
from landscape.robot.tool_shapes import FINGER, FINGER_FORCE, GRIPPER_BODY, PLATE_T

_ARRIVED = 5e-4           # m, a finger this close to its target has arrived
_SUCTION_REACH = 0.002    # m, a part this close to the cup face is sucked on
_HOLD_FORCE = 500.0       # N, limit of the holding constraints


@dataclass(frozen=True)
class Part:
    """A part body: its name, pybullet body id and box size (full extents, m)."""

    name: str
    body: int
    size: tuple[float, float, float]


# ---- frames -----------------------------------------------------------------------------------

def rotation(orn) -> np.ndarray:
    """3x3 rotation matrix of a quaternion xyzw."""
    return np.array(pb.getMatrixFromQuaternion(orn)).reshape(3, 3)


def set_sleeping(bc, body: int, allowed: bool) -> None:
    """Let a resting body sleep (the solver skips it: parts on the table and tools in the rack
    cost nothing), or keep it awake and wake it (a mounted tool, a held part)."""
    if allowed:
        bc.changeDynamics(body, -1, activationState=pb.ACTIVATION_STATE_ENABLE_SLEEPING)
    else:
        bc.changeDynamics(body, -1, activationState=pb.ACTIVATION_STATE_DISABLE_SLEEPING)
        bc.changeDynamics(body, -1, activationState=pb.ACTIVATION_STATE_WAKE_UP)


def angle_between(orn_a, orn_b) -> float:
    """Angle (rad) of the rotation taking frame a to frame b."""
    return pin.Quaternion(np.array(orn_a)).angularDistance(pin.Quaternion(np.array(orn_b)))


# ---- mechanics --------------------------------------------------------------------------------

class Tool:
    """A tool body in a physics client `bc` (a BulletClient): where it is, holding parts."""

    def __init__(self, bc, spec: ToolSpec, body: int, parts: dict[str, Part]):
        self.bc, self.spec, self.body, self.parts = bc, spec, body, parts
        self.name = spec.name
        self.links = [-1] + list(range(bc.getNumJoints(body)))
        info = bc.getDynamicsInfo(body, -1)
        # pybullet places bodies by their centre of mass; these convert to the plate frame.
        self.com_in_plate = (info[3], info[4])
        self.plate_in_com = bc.invertTransform(info[3], info[4])
        self.held: int | None = None     # body id of the part held
        self._hold: int | None = None    # its constraint
        for link in self.links:
            bc.changeDynamics(body, link, contactStiffness=spec.contact_stiffness,
                              contactDamping=spec.contact_damping)

    def plate_pose(self):
        pos, orn = self.bc.getBasePositionAndOrientation(self.body)
        return self.bc.multiplyTransforms(pos, orn, *self.plate_in_com)

    def tip_pose(self):
        return self.bc.multiplyTransforms(*self.plate_pose(), (0, 0, self.spec.length),
                                          (0, 0, 0, 1))

    def place(self, pos, orn) -> None:
        """Put the plate frame at (pos, orn), at rest."""
        self.bc.resetBasePositionAndOrientation(
            self.body, *self.bc.multiplyTransforms(pos, orn, *self.com_in_plate))
        self.bc.resetBaseVelocity(self.body, (0, 0, 0), (0, 0, 0))

    def to_tool(self, point) -> np.ndarray:
        """A world point in the plate frame."""
        pos, orn = self.plate_pose()
        return rotation(orn).T @ (np.asarray(point) - pos)

    # -- holding parts
    def grab(self, part: int) -> None:
        """Hold `part` where it is now relative to the tool."""
        if self.held is not None:
            return
        tpos, torn = self.bc.getBasePositionAndOrientation(self.body)
        ppos, porn = self.bc.getBasePositionAndOrientation(part)
        rel = self.bc.multiplyTransforms(*self.bc.invertTransform(tpos, torn), ppos, porn)
        self._hold = self.bc.createConstraint(self.body, -1, part, -1, pb.JOINT_FIXED, (0, 0, 0),
                                              rel[0], (0, 0, 0), rel[1], (0, 0, 0, 1))
        self.bc.changeConstraint(self._hold, maxForce=_HOLD_FORCE)
        self._collide(part, False)
        set_sleeping(self.bc, part, False)
        self.held = part

    def drop(self, *, restore_collisions: bool = True) -> None:
        if self.held is None:
            return
        self.bc.removeConstraint(self._hold)
        if restore_collisions:
            self._collide(self.held, True)
        set_sleeping(self.bc, self.held, True)
        self.held, self._hold = None, None

    def _collide(self, part: int, enable: bool) -> None:
        for link in self.links:
            self.bc.setCollisionFilterPair(self.body, part, link, -1, int(enable))

    # -- per tool kind
    def actuate(self, wire: str, value: bool) -> None:
        """An output of the cell changed (only called while mounted)."""

    def unmounted(self) -> None:
        """The changer let go: air and signals are cut."""

    def update(self) -> None:
        """Once per cycle while mounted; cheap when nothing happens."""

    def input(self, wire: str) -> bool:
        return False


class ParallelGripper(Tool):
    """Two fingers closing symmetrically along the tool x axis (output gripper_close).

    Closing, the fingers take a part whose centre lies between them (centring it across the
    fingers) and stop on it; `gripper_closed` reads 1 once the fingers have arrived, on the
    part or fully closed. Opening drops the part at once.
    """

    def __init__(self, bc, spec, body, parts):
        super().__init__(bc, spec, body, parts)
        self._fingers = [0, 1]
        self._target = spec.stroke / 2
        self._closing = False
        self._moving = False
        self._closed = False
        self._candidate: int | None = None
        self._released: int | None = None
        self._drive(self._target)
        for j in self._fingers:
            bc.resetJointState(body, j, self._target)

    def _drive(self, d: float) -> None:
        for j in self._fingers:
            self.bc.setJointMotorControl2(self.body, j, pb.POSITION_CONTROL, targetPosition=d,
                                          force=FINGER_FORCE, maxVelocity=self.spec.finger_speed)

    def _between_fingers(self) -> tuple[int | None, float]:
        """The part between the fingers (its centre between them across and along them, and
        some of its height within their length), and its width across them (m)."""
        gap = 2 * self.bc.getJointState(self.body, 0)[0]
        top = PLATE_T + GRIPPER_BODY
        _, torn = self.plate_pose()
        tool = rotation(torn)
        for part in self.parts.values():
            ppos, porn = self.bc.getBasePositionAndOrientation(part.body)
            c = self.to_tool(ppos)
            extent = np.abs(tool.T @ rotation(porn)) @ np.asarray(part.size) / 2
            if (abs(c[0]) < gap / 2 and abs(c[1]) < FINGER[1]
                    and top < c[2] + extent[2] and c[2] - extent[2] < self.spec.length):
                width = 2 * float(extent[0])
                if width < gap:
                    return part.body, width
        return None, 0.0

    def actuate(self, wire, value):
        if wire != "gripper_close" or value == self._closing:
            return
        self._closing, self._closed, self._moving = value, False, True
        if value:
            self._candidate, width = self._between_fingers()
            if self._released is not None and self._released != self._candidate:
                self._collide(self._released, True)     # closed again before fully open
            self._released = None
            if self._candidate is not None:
                self._collide(self._candidate, False)
            self._target = width / 2
        else:
            # Collisions with the part come back once the fingers are open again.
            self._released = self.held if self.held is not None else self._candidate
            self._candidate = None
            self.drop(restore_collisions=False)
            self._target = self.spec.stroke / 2
        self._drive(self._target)

    def update(self):
        if not self._moving:
            return
        d = [s[0] for s in self.bc.getJointStates(self.body, self._fingers)]
        if max(abs(x - self._target) for x in d) > _ARRIVED:
            return
        self._moving = False
        if self._closing:
            self._closed = True
            if self._candidate is not None:
                self._centre(self._candidate)
                self.grab(self._candidate)
                self._candidate = None
        elif self._released is not None:
            self._collide(self._released, True)
            self._released = None

    def _centre(self, part: int) -> None:
        """Slide the part across the fingers onto the tool axis, as closing fingers do."""
        ppos, porn = self.bc.getBasePositionAndOrientation(part)
        _, torn = self.plate_pose()
        x_axis = rotation(torn)[:, 0]
        shift = -float(self.to_tool(ppos)[0]) * x_axis
        self.bc.resetBasePositionAndOrientation(part, np.asarray(ppos) + shift, porn)

    def input(self, wire):
        return wire == "gripper_closed" and self._closed


class VacuumCup(Tool):
    """A suction cup at the tip (output vacuum_on): with suction on, a part touching the cup
    face is held; `vacuum_ok` reads 1 while a part is held. Suction off drops it."""

    def __init__(self, bc, spec, body, parts):
        super().__init__(bc, spec, body, parts)
        self._on = False

    def actuate(self, wire, value):
        if wire != "vacuum_on":
            return
        self._on = value
        if not value:
            self.drop()

    def unmounted(self):
        self.actuate("vacuum_on", False)

    def update(self):
        if not self._on or self.held is not None:
            return
        tip, _ = self.tip_pose()
        for part in self.parts.values():
            body = part.body
            ppos, _ = self.bc.getBasePositionAndOrientation(body)
            # Cheap pre-filter: only parts whose centre is near the cup.
            if np.sum((np.asarray(ppos) - tip) ** 2) > 0.04:
                continue
            for point in self.bc.getClosestPoints(self.body, body, _SUCTION_REACH, -1, -1):
                c = self.to_tool(point[5])
                if (c[2] > self.spec.length - _SUCTION_REACH
                        and np.hypot(c[0], c[1]) <= self.spec.cup_radius + _SUCTION_REACH):
                    self.grab(body)
                    return

    def input(self, wire):
        return wire == "vacuum_ok" and self._on and self.held is not None


TOOL_CLASSES = {"parallel_gripper": ParallelGripper, "vacuum_cup": VacuumCup}
