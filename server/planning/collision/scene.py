"""The collision scene: the cell as the checker sees it, following the world through explicit
calls (the server knows what it commanded; nothing here reads the simulator).

Built from the cell file: the arm's links, the fixtures, the tools standing in their rack slots,
the loose parts and (if the cell has one) the floor. Then:

- mount_tool / unmount_tool: a tool moves from its slot to the flange (its plate frame on
  tool0, as ToolSpec says) and back, or is left where the flange let it go;
- set_finger_gap: the mounted gripper's fingers (open: its stroke);
- attach_part: a part moves with the tool (in its present pose relative to the flange, or a
  given one); release_part leaves it where it is; place_part puts it down at a pose (an
  obstacle there); remove_part takes it out of the cell; follow_parts takes the poses the
  world reports for the parts lying loose (server/world_parts.py);
- allow / forbid: allowed contacts kept until forbidden; `grasp` names the usual one for a
  single check. Coupling a tool and putting it back need none: the model allows the bare
  flange on an unmounted tool, and a mounted tool on its rack, in the tool's docking corridor
  (docking.py).

`model()` returns the compiled, immutable CollisionModel of the present state (cached until the
next change); checks run on it (check.py), so a change never disturbs a check in progress.
Poses are (4, 4) in the world frame, metres; joint vectors (6,) rad. Thread-safe.
"""
from __future__ import annotations

import copy
import threading

import coal
import numpy as np
import pinocchio as pin

from landscape.robot.units import pose_matrix
from landscape.robot.cell import Cell
from landscape.robot.kinematics import Kinematics

from .docking import Dock
from .model import DEFAULT_MARGIN, AllowedContact, CollisionModel, CollisionModelError
from .shapes import (ARM_LINKS, FLANGE_LINK, FLOOR, Geometry, arm_description, box_geometry,
                     floor_geometry, tool_geometries)

MOVED, TURNED = 0.001, 0.01   # m, rad: a part that moved less stays where the scene has it


class CollisionScene:
    """What is where in the cell, for collision checking."""

    def __init__(self, cell: Cell, margin: float = DEFAULT_MARGIN):
        if not margin > 0:
            raise CollisionModelError(f"the margin must be positive, got {margin!r} m")
        self.cell, self.margin = cell, float(margin)
        self._lock = threading.Lock()
        self._base = pose_matrix(cell.base.xyz, cell.base.rpy)      # base_link in the world
        self._world_in_base = np.linalg.inv(self._base)
        self._tools = {t.name: t for t in cell.world.tools}
        self._parts = {p.name: p for p in cell.world.parts}
        self._gap = {t.name: t.stroke for t in cell.world.tools}    # m, fingers open
        self._tool_at = {t.name: pose_matrix(t.slot.xyz, t.slot.rpy) for t in cell.world.tools}
        self._part_at = {p.name: pose_matrix(p.pose.xyz, p.pose.rpy) for p in cell.world.parts}
        self._mounted: str | None = None
        self._held: tuple[str, np.ndarray] | None = None     # part, its pose in the flange
        self._allowed: list[AllowedContact] = []
        self._known = (frozenset(ARM_LINKS) | {f.name for f in cell.world.fixtures}
                       | set(self._tools) | set(self._parts)
                       | ({FLOOR} if cell.world.floor else set()))
        self._kinematics = Kinematics(cell.arm)
        self._rack = {t.name: self._slot_fixtures(t) for t in cell.world.tools}
        self._model: CollisionModel | None = None
        self.version = 0        # changes so far

    # ---- what is where ------------------------------------------------------------------------

    @property
    def mounted(self) -> str | None:
        """The tool on the flange, or None."""
        return self._mounted

    @property
    def held(self) -> str | None:
        """The part moving with the tool, or None."""
        return self._held[0] if self._held else None

    def tool_pose(self, name: str) -> np.ndarray | None:
        """Where an unmounted tool's plate stands (4, 4, world); None while mounted."""
        self._tool(name)
        pose = self._tool_at.get(name)
        return None if pose is None else pose.copy()

    def part_pose(self, name: str) -> np.ndarray | None:
        """Where a part lies (4, 4, world, its centre); None while held or removed."""
        self._part(name)
        pose = self._part_at.get(name)
        return None if pose is None else pose.copy()

    def copy(self) -> "CollisionScene":
        """A scene in the same state, to change without changing this one (to check what a
        tool change will make of it before it starts)."""
        with self._lock:
            return copy.copy(self)

    def __copy__(self) -> "CollisionScene":
        """copy.copy: a lock of its own, and its own copies of what changes."""
        other = object.__new__(type(self))
        vars(other).update(vars(self), _lock=threading.Lock(), _gap=dict(self._gap),
                           _tool_at=dict(self._tool_at), _part_at=dict(self._part_at),
                           _allowed=list(self._allowed))
        return other

    def state(self) -> tuple:
        """What has changed in this scene since it was built from its cell: for `restore` on
        a scene of the same cell in another process (planning_process.py)."""
        with self._lock:
            return (self.version, dict(self._gap), dict(self._tool_at), dict(self._part_at),
                    self._mounted, self._held, tuple(self._allowed))

    def restore(self, state: tuple) -> None:
        """This scene as `state` (another's, from `state()`) says; nothing to do if it was
        taken from there at the same version."""
        with self._lock:
            if state[0] == self.version:
                return
            (self.version, self._gap, self._tool_at, self._part_at, self._mounted, self._held,
             allowed) = state
            self._allowed = list(allowed)
            self._model = None

    # ---- the world changes --------------------------------------------------------------------

    def mount_tool(self, name: str) -> None:
        """The tool changer took `name` onto the flange."""
        with self._lock:
            self._tool(name)
            if self._mounted is not None:
                raise CollisionModelError(f"{self._mounted} is mounted already")
            self._mounted = name
            del self._tool_at[name]
            self._changed()

    def unmount_tool(self, at: np.ndarray | None = None) -> str:
        """The changer let the mounted tool go: into its rack slot (at None) or with its plate
        at `at` (4, 4, world). A held part is left where it is first (release_part)."""
        with self._lock:
            if self._mounted is None:
                raise CollisionModelError("no tool is mounted")
            if self._held is not None:
                raise CollisionModelError(f"the tool holds {self._held[0]}: release it first")
            name, self._mounted = self._mounted, None
            slot = self._tools[name].slot
            self._tool_at[name] = (pose_matrix(slot.xyz, slot.rpy) if at is None
                                   else _pose(at, "at"))
            self._changed()
            return name

    def set_finger_gap(self, gap: float) -> None:
        """The mounted gripper's fingers stand `gap` (m) apart (0 closed, its stroke open)."""
        with self._lock:
            tool = self._tools.get(self._mounted)
            if tool is None or tool.kind != "parallel_gripper":
                raise CollisionModelError("no gripper is mounted")
            if not 0.0 <= gap <= tool.stroke:
                raise CollisionModelError(f"the finger gap must be within [0, {tool.stroke}] m, "
                                          f"got {gap!r}")
            self._gap[tool.name] = float(gap)
            self._changed()

    def attach_part(self, name: str, q=None, in_flange: np.ndarray | None = None) -> None:
        """`name` now moves with the flange: where it lies relative to the flange at joints q
        (6,) rad, or at `in_flange` (4, 4: its centre in the flange frame)."""
        with self._lock:
            self._part(name)
            if self._held is not None:
                raise CollisionModelError(f"{self._held[0]} is held already")
            if (q is None) == (in_flange is None):
                raise CollisionModelError("attach_part needs either q or in_flange")
            if in_flange is None:
                lying = self._part_at.get(name)
                if lying is None:
                    raise CollisionModelError(f"{name} is not in the cell")
                in_flange = np.linalg.inv(self._flange_world(q)) @ lying
            self._part_at.pop(name, None)
            self._held = (name, _pose(in_flange, "in_flange"))
            self._changed()

    def release_part(self, q) -> np.ndarray:
        """The tool let go at joints q (6,): the held part stays where it is, an obstacle now.
        Returns its pose (4, 4, world)."""
        with self._lock:
            if self._held is None:
                raise CollisionModelError("no part is held")
            name, in_flange = self._held
            self._part_at[name] = self._flange_world(q) @ in_flange
            self._held = None
            self._changed()
            return self._part_at[name].copy()

    def follow_parts(self, poses: dict[str, np.ndarray], version: int) -> bool:
        """The parts lying loose where the world has them: `poses` (4, 4, world) read when the
        scene was at `version`. Nothing changes if the scene changed since (the read may
        predate that change; the next one will not), nor for a part held, nor for a pose
        within MOVED and TURNED of the scene's (a change recompiles the model). True if
        the poses were taken."""
        with self._lock:
            if version != self.version:
                return False
            for name, pose in poses.items():
                self._part(name)
                pose, now = _pose(pose, name), self._part_at.get(name)
                if self.held != name and (now is None or not _near(now, pose)):
                    self._part_at[name] = pose
                    self._changed()
            return True

    def place_part(self, name: str, pose: np.ndarray) -> None:
        """Put part `name` down with its centre at `pose` (4, 4, world); held, it is let go."""
        with self._lock:
            self._part(name)
            if self._held is not None and self._held[0] == name:
                self._held = None
            self._part_at[name] = _pose(pose, "pose")
            self._changed()

    def remove_part(self, name: str) -> None:
        """Take part `name` out of the cell (held or lying)."""
        with self._lock:
            self._part(name)
            if self._held is not None and self._held[0] == name:
                self._held = None
            self._part_at.pop(name, None)
            self._changed()

    # ---- allowed contacts ---------------------------------------------------------------------

    def allow(self, *contacts: AllowedContact) -> None:
        """Allow these contacts in every check until forbidden (by reason)."""
        with self._lock:
            for c in contacts:
                self._names(c.a, c.b)
            self._allowed += [c for c in contacts if c not in self._allowed]
            self._changed()

    def forbid(self, reason: str) -> None:
        """Withdraw the allowed contacts named `reason`."""
        with self._lock:
            kept = [c for c in self._allowed if c.reason != reason]
            if len(kept) == len(self._allowed):
                raise CollisionModelError(f"no allowed contact is named {reason!r}")
            self._allowed = kept
            self._changed()

    def grasp(self, part: str) -> AllowedContact:
        """The mounted tool closing on (or sucking at) `part`."""
        self._part(part)
        if self._mounted is None:
            raise CollisionModelError("no tool is mounted")
        return AllowedContact(f"grasp {part}", self._mounted, part)

    # ---- the compiled model -------------------------------------------------------------------

    def model(self) -> CollisionModel:
        """The present scene, compiled (the same object until the scene changes)."""
        with self._lock:
            if self._model is None:
                self._model = CollisionModel(self.cell.arm, self._base, self._geometries(),
                                             self._known, self._allowed, self.margin,
                                             self._docks())
            return self._model

    def _docks(self) -> list[Dock]:
        """The contacts allowed in a docking corridor (docking.py): the bare flange on each
        unmounted tool, or the mounted tool on what its own rack slot stands on."""
        world = self.cell.world

        def dock(a: str, b: str, plate: np.ndarray) -> Dock:
            return Dock(a, b, self._world_in_base @ plate, world.lock_distance, world.lock_angle)
        if self._mounted is None:
            return [dock(ARM_LINKS[FLANGE_LINK], name, pose)
                    for name, pose in self._tool_at.items()]
        slot = self._tools[self._mounted].slot
        return [dock(self._mounted, f, pose_matrix(slot.xyz, slot.rpy))
                for f in self._rack[self._mounted]]

    def _geometries(self) -> list[Geometry]:
        _, out = arm_description(self.cell.arm)
        out = list(out)
        if self._mounted is not None:
            spec = self._tools[self._mounted]
            out += tool_geometries(spec, self._gap[spec.name], FLANGE_LINK, np.eye(4))
        if self._held is not None:
            name, in_flange = self._held
            out.append(box_geometry(self._parts[name], FLANGE_LINK, in_flange))
        in_base = self._world_in_base
        out += [box_geometry(f, 0, in_base @ pose_matrix(f.pose.xyz, f.pose.rpy))
                for f in self.cell.world.fixtures]
        for name, pose in self._tool_at.items():
            out += tool_geometries(self._tools[name], self._gap[name], 0, in_base @ pose)
        out += [box_geometry(self._parts[name], 0, in_base @ pose)
                for name, pose in self._part_at.items()]
        if self.cell.world.floor:
            out.append(floor_geometry(in_base))
        return out

    # ---- helpers ------------------------------------------------------------------------------

    def _slot_fixtures(self, spec) -> list[str]:
        """The fixtures a tool stands on in its rack slot (within the margin of it there)."""
        slot = self._world_in_base @ pose_matrix(spec.slot.xyz, spec.slot.rpy)
        shapes = tool_geometries(spec, spec.stroke, 0, slot)
        return [f.name for f in self.cell.world.fixtures
                if min(_distance(s, box_geometry(f, 0, self._world_in_base @ pose_matrix(
                    f.pose.xyz, f.pose.rpy))) for s in shapes) < self.margin]

    def _changed(self) -> None:
        self._model = None
        self.version += 1

    def _flange_world(self, q) -> np.ndarray:
        q = np.asarray(q, dtype=float)
        if q.shape != (6,) or not np.all(np.isfinite(q)):
            raise CollisionModelError(f"joints must be 6 finite values (rad), got {q!r}")
        return self._base @ self._kinematics.forward(q)

    def _tool(self, name: str):
        if name not in self._tools:
            raise CollisionModelError(f"unknown tool {name!r}; the cell has "
                                      f"{', '.join(self._tools) or 'none'}")
        return self._tools[name]

    def _part(self, name: str):
        if name not in self._parts:
            raise CollisionModelError(f"unknown part {name!r}; the cell has "
                                      f"{', '.join(self._parts) or 'none'}")
        return self._parts[name]

    def _names(self, *names: str) -> None:
        unknown = sorted(set(names) - self._known)
        if unknown:
            raise CollisionModelError(f"unknown body {', '.join(unknown)}")


def _pose(T, name: str) -> np.ndarray:
    T = np.asarray(T, dtype=float)
    if T.shape != (4, 4) or not np.all(np.isfinite(T)):
        raise CollisionModelError(f"{name} must be a finite (4, 4) pose")
    return T.copy()


def _near(a: np.ndarray, b: np.ndarray) -> bool:
    """Two poses within MOVED and TURNED of each other."""
    turned = np.linalg.norm(pin.log3(a[:3, :3].T @ b[:3, :3]))
    return bool(np.linalg.norm(a[:3, 3] - b[:3, 3]) < MOVED and turned < TURNED)


def _distance(a: Geometry, b: Geometry) -> float:
    """Signed distance (m) of two fixed shapes (placements in one frame)."""
    result = coal.DistanceResult()
    return coal.distance(a.shape, coal.Transform3s(a.placement[:3, :3], a.placement[:3, 3]),
                         b.shape, coal.Transform3s(b.placement[:3, :3], b.placement[:3, 3]),
                         coal.DistanceRequest(), result)
