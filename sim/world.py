"""The pybullet world of a cell: floor, fixtures, parts, tools in their rack, the arm; and the
tool changer that couples tools to the flange.

Everything lives in one physics client (a `BulletClient` the controller owns); nothing here
steps the simulation. The controller calls `update()` once per cycle after stepping, and
`set_output()` when a wired output changes; inputs wired to the world are read on demand
through `read_input()`.

Frames: (position (3,) m, quaternion xyzw (4,)) in the world. The arm's base_link is placed at
`cell.base`; the flange frame is the URDF link tool0.
"""
from __future__ import annotations

import math
import os
import tempfile

import numpy as np
import pybullet as pb

from landscape.robot.arm import urdf
from landscape.robot.cell import BoxSpec, Cell, Pose
from landscape.robot.tool_shapes import tool_urdf
from landscape.sim.tools import TOOL_CLASSES, Part, Tool, angle_between, set_sleeping

_OFF_TABLE = (-1.5, 1.5)   # m, where `remove_part` puts parts down on the floor (x, y)


def quaternion(pose: Pose):
    return pb.getQuaternionFromEuler(pose.rpy)


def _load_urdf(bc, text: str, **kwargs) -> int:
    """Load URDF text: pybullet reads URDF only from files, so go through a temporary one."""
    fd, path = tempfile.mkstemp(suffix=".urdf", prefix="landscape-")
    try:
        with os.fdopen(fd, "w") as f:
            f.write(text)
        return bc.loadURDF(path, **kwargs)
    finally:
        os.unlink(path)


class World:
    """The cell's bodies and mechanics in the physics client `bc`."""

    def __init__(self, bc, cell: Cell):
        self.bc, self.cell = bc, cell
        spec = cell.world
        bc.setGravity(*spec.gravity)
        self.floor: int | None = None
        if spec.floor:
            self.floor = bc.createMultiBody(0, bc.createCollisionShape(pb.GEOM_PLANE))
        self.fixtures = {f.name: self._box(f) for f in spec.fixtures}
        self.parts = {p.name: Part(p.name, self._box(p), p.size) for p in spec.parts}
        self.zones = {z.name: z for z in spec.zones}
        self.arm = _load_urdf(bc, urdf(cell.arm), basePosition=cell.base.xyz,
                              baseOrientation=quaternion(cell.base), useFixedBase=True,
                              flags=pb.URDF_USE_INERTIA_FROM_FILE)
        names = [bc.getJointInfo(self.arm, i)[1].decode() for i in range(bc.getNumJoints(self.arm))]
        self.joints = [names.index(f"joint_{i + 1}") for i in range(6)]
        self.flange_joint = names.index("flange")
        self.flange_link = self.flange_joint          # pybullet: link i is the child of joint i
        self.arm_links = [-1] + list(range(len(names)))
        # The flange disk (link6) and tool0 never collide with tools: the changer's faces mate
        # there (and pybullet's cylinder margins would make them touch a few mm early).
        self._flange_side = (self.joints[5], self.flange_link)
        for i, q in zip(self.joints, cell.controller.initial_position):
            bc.resetJointState(self.arm, i, q)
        self.tools: dict[str, Tool] = {}
        self._docks: dict[str, int] = {}
        for t in spec.tools:
            body = _load_urdf(bc, tool_urdf(t), basePosition=t.slot.xyz,
                              baseOrientation=quaternion(t.slot),
                              flags=pb.URDF_USE_INERTIA_FROM_FILE)
            tool = TOOL_CLASSES[t.kind](bc, t, body, self.parts)
            self.tools[t.name] = tool
            self._collide_with_arm(tool, True)
            self._dock(tool)
        self.mounted: Tool | None = None
        self._coupling: int | None = None
        self._outputs: dict[str, bool] = {}

    def _box(self, spec: BoxSpec) -> int:
        half = [s / 2 for s in spec.size]
        shape = self.bc.createCollisionShape(pb.GEOM_BOX, halfExtents=half)
        visual = self.bc.createVisualShape(pb.GEOM_BOX, halfExtents=half, rgbaColor=spec.color)
        body = self.bc.createMultiBody(spec.mass, shape, visual, spec.pose.xyz,
                                       quaternion(spec.pose))
        if spec.mass > 0:
            self.bc.changeDynamics(body, -1, lateralFriction=0.8)
            set_sleeping(self.bc, body, True)
        return body

    # ---- frames -------------------------------------------------------------------------------

    def flange_pose(self):
        """The flange frame (tool0) in the world."""
        s = self.bc.getLinkState(self.arm, self.flange_link, computeForwardKinematics=True)
        return s[4], s[5]

    def tip_pose(self):
        """The mounted tool's tip frame in the world; the flange when no tool is mounted."""
        return self.mounted.tip_pose() if self.mounted is not None else self.flange_pose()

    def _near(self, a, b) -> bool:
        spec = self.cell.world
        return (math.dist(a[0], b[0]) <= spec.lock_distance
                and angle_between(a[1], b[1]) <= spec.lock_angle)

    # ---- tool changer and rack ----------------------------------------------------------------

    def _dock(self, tool: Tool) -> None:
        """Hold the tool in its rack slot (the rack's pins), exactly at the slot pose."""
        slot = tool.spec.slot
        tool.place(slot.xyz, quaternion(slot))
        set_sleeping(self.bc, tool.body, True)
        self._docks[tool.name] = self.bc.createConstraint(
            tool.body, -1, -1, -1, pb.JOINT_FIXED, (0, 0, 0), tool.plate_in_com[0], slot.xyz,
            tool.plate_in_com[1], quaternion(slot))

    def _couple(self, tool: Tool) -> None:
        if tool.name in self._docks:
            self.bc.removeConstraint(self._docks.pop(tool.name))
        tool.place(*self.flange_pose())
        set_sleeping(self.bc, tool.body, False)
        self._coupling = self.bc.createConstraint(
            self.arm, self.flange_link, tool.body, -1, pb.JOINT_FIXED, (0, 0, 0), (0, 0, 0),
            tool.plate_in_com[0], (0, 0, 0, 1), tool.plate_in_com[1])
        self.bc.changeConstraint(self._coupling, maxForce=1e5)
        self._collide_with_arm(tool, False)
        self.mounted = tool
        for wire, value in self._outputs.items():   # air and signals now reach the tool
            tool.actuate(wire, value)

    def _uncouple(self) -> None:
        tool, self.mounted = self.mounted, None
        self.bc.removeConstraint(self._coupling)
        self._coupling = None
        tool.unmounted()
        self._collide_with_arm(tool, True)
        set_sleeping(self.bc, tool.body, True)
        slot = tool.spec.slot
        if self._near(tool.plate_pose(), (slot.xyz, quaternion(slot))):
            self._dock(tool)

    def _collide_with_arm(self, tool: Tool, enable: bool) -> None:
        for a in self.arm_links:
            for t in tool.links:
                on = enable and a not in self._flange_side
                self.bc.setCollisionFilterPair(self.arm, tool.body, a, t, int(on))

    def _tool_at_flange(self) -> Tool | None:
        flange = self.flange_pose()
        for tool in self.tools.values():
            if tool is not self.mounted and self._near(tool.plate_pose(), flange):
                return tool
        return None

    # ---- I/O ----------------------------------------------------------------------------------

    def set_output(self, wire: str, value: bool) -> None:
        """An output wired to the world changed (called on changes only)."""
        self._outputs[wire] = value
        if wire == "toolchanger_lock":
            if value and self.mounted is None:
                tool = self._tool_at_flange()
                if tool is not None:
                    self._couple(tool)
            elif not value and self.mounted is not None:
                self._uncouple()
        elif self.mounted is not None:
            self.mounted.actuate(wire, value)

    def read_input(self, wire: str) -> bool:
        """The present value of a world-wired input (cell.WORLD_INPUT_WIRES, zone:<name> or
        tool_id:<bit>)."""
        if wire.startswith("zone:"):
            return self.part_in_zone(wire[5:])
        if wire.startswith("tool_id:"):
            return self.mounted is not None and bool(self.mounted.spec.id >> int(wire[8:]) & 1)
        if wire == "tool_present":
            return self.mounted is not None or self._tool_at_flange() is not None
        return self.mounted is not None and self.mounted.input(wire)

    def part_in_zone(self, zone: str) -> bool:
        z = self.zones[zone]
        return any(z.contains(self.bc.getBasePositionAndOrientation(p.body)[0])
                   for p in self.parts.values())

    def update(self) -> None:
        """Once per cycle, after the physics step."""
        if self.mounted is not None:
            self.mounted.update()

    # ---- what a person does -------------------------------------------------------------------

    def part_pose(self, name: str):
        return self.bc.getBasePositionAndOrientation(self.parts[name].body)

    def part_states(self) -> dict[str, tuple]:
        """Every part: (position (3,) m, quaternion xyzw, speed m/s, held by the mounted tool),
        for the server's collision scene to follow what physics and people did."""
        held = self.mounted.held if self.mounted is not None else None
        out = {}
        for name, part in self.parts.items():
            pos, orn = self.bc.getBasePositionAndOrientation(part.body)
            speed = float(np.linalg.norm(self.bc.getBaseVelocity(part.body)[0]))
            out[name] = (tuple(pos), tuple(orn), speed, part.body == held)
        return out

    def place_part(self, name: str, xyz, rpy=(0.0, 0.0, 0.0)) -> None:
        """Put a part down by hand at xyz (m) with fixed-axis angles rpy (rad), at rest; a
        gripper or cup holding it lets go."""
        part = self.parts[name]
        for tool in self.tools.values():
            if tool.held == part.body:
                tool.drop()
        self.bc.resetBasePositionAndOrientation(part.body, xyz, pb.getQuaternionFromEuler(rpy))
        self.bc.resetBaseVelocity(part.body, (0, 0, 0), (0, 0, 0))
        self.bc.changeDynamics(part.body, -1, activationState=pb.ACTIVATION_STATE_WAKE_UP)

    def remove_part(self, name: str) -> None:
        """Take a part out of the cell: it is put down on the floor, well out of reach."""
        i = list(self.parts).index(name)
        size = self.parts[name].size
        self.place_part(name, (_OFF_TABLE[0], _OFF_TABLE[1] + 0.3 * i, size[2] / 2))

    def base_matrix(self) -> np.ndarray:
        """The arm base_link in the world, 4x4."""
        t = np.eye(4)
        t[:3, :3] = np.array(pb.getMatrixFromQuaternion(quaternion(self.cell.base))).reshape(3, 3)
        t[:3, 3] = self.cell.base.xyz
        return t
