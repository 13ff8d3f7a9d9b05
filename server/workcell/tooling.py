"""The end effector (seed 3.8.1): tools fetched from and returned to the rack, their functions,
and their state, over the cell's digital I/O.

The rack and its tools come from the cell file (id, kind, slot, length); what the tool changer
and the tools do is read and written through named I/O signals, as on a real cell:
  toolchanger_lock (output)  1 couples the tool whose plate is at the flange, 0 releases it
  tool_id_<bit> (inputs)     the coupled tool's id, coded on the changer's pins (0: no tool)
  gripper_close / gripper_closed, vacuum_on / vacuum_ok: a tool kind's function and its
  confirmation (FUNCTIONS below). Function bit 0 of activate/deactivateTool is the main one.

GetTool(tool): with the functions off, the flange goes (joint move, set speed) to the slot's
approach point APPROACH above the plate, straight down (at most TOOL_CHANGE_SPEED %) onto it,
the changer locks, the id inputs must name the tool, then straight up clear of the rack
(the tool's length plus CLEARANCE). The tool offset becomes the tool's tip (plate to tip
along z). PutTool reverses it: down into the slot, functions off, unlock, the id inputs must
read 0, straight up; the tool offset becomes the flange. All the steps are planned, each from
where the one before ends, and checked against the cell before the first one moves (the last
one against the cell as the coupling or uncoupling leaves it), so a blocked slot refuses the
command with the arm where it was. Each step then runs as a motion of its own (the same
events, stops and aborts as any move, checked again as it starts); a step that does not end
"done" fails the command, naming the step, and leaves the arm where that step left it. A tool
already on the flange is not fetched again; another one must be put away first.

ActivateTool closes the gripper (blocking until `gripper_closed` reads 1, on a part or empty)
or switches the cup's suction on (blocking for two cycles; `vacuum_ok` then says whether a part
is held). DeactivateTool opens the gripper (blocking for its rated opening time: there is no
"open" input) or switches the suction off. Whenever the flange's load changes (a tool coupled or released, a part taken or let go) the
cycle is told its mass properties (arm_dynamics.py), for the model torques it reports. The
state (GetEndEffectorState, state streams) is read from the ring's I/O image, at most a cycle
old: the tool from its id inputs, and per kind: gripper "open", "closing" or "closed"; cup
"off", "suction_on" or "holding" (a part held).
"""
from __future__ import annotations

import time
from dataclasses import dataclass
import numpy as np

from landscape.robot.cell import Pose, ToolSpec
from landscape.robot.controller import IoUnit, Status
from landscape.robot.kinematics import Kinematics
from landscape.robot.units import pose_matrix
from landscape.server.cycle.arm_dynamics import NO_PAYLOAD, part_payload, tool_payload
from landscape.server.device.motion_control import MotionControl
from landscape.server.device.stored_settings import SettingsKeeper
from landscape.server.errors import ControllerFailure, OutOfRange, ParamError, WrongState
from landscape.server.link.controller_link import ControllerLink
from landscape.server.planning.collision import CollisionScene
from landscape.server.workcell.world_parts import WorldParts

LOCK, ID_PREFIX = "toolchanger_lock", "tool_id_"
APPROACH = 0.1             # m above the plate in its slot, where a tool change starts and ends
CLEARANCE = 0.05           # m between a carried tool's tip and the rack, leaving it
TOOL_CHANGE_SPEED = 10.0   # % of maximum speed: the fine moves in and out of the slot
COUPLE_TIMEOUT = 0.5       # s (controller time) for the changer to report the tool
CLOSE_TIMEOUT = 2.0        # s for a gripper to report closed
SLOT_REACH = 0.005         # m: the flange this close to a slot has its tool in the rack
GRASP_REACH = 0.03         # m: a part whose centre is this close to the tip is the one taken


@dataclass(frozen=True)
class Functions:
    """A tool kind's main function: its output, its confirming input, and the states named
    off, on but not confirmed, on and confirmed."""

    output: str
    confirm: str
    states: tuple[str, str, str]


FUNCTIONS = {
    "parallel_gripper": Functions("gripper_close", "gripper_closed", ("open", "closing", "closed")),
    "vacuum_cup": Functions("vacuum_on", "vacuum_ok", ("off", "suction_on", "holding")),
}


class Tooling:
    """`tools`, `parts` (BoxSpec), `base`: the cell file's; `world`: None if not tracked."""
    def __init__(self, link: ControllerLink, motions: MotionControl, kinematics: Kinematics,
                 collisions: CollisionScene, settings: SettingsKeeper, world: WorldParts | None,
                 tools: tuple[ToolSpec, ...], parts, base: Pose):
        self.link, self.motions, self.kinematics = link, motions, kinematics
        self.collisions, self.settings, self.world = collisions, settings, world
        self._parts, self.tools = {p.name: p for p in parts}, {t.name: t for t in tools}
        self._by_id = {t.id: t for t in tools}
        self._world_base = pose_matrix(base.xyz, base.rpy)   # base_link in the cell's world
        self._slots = {t.name: np.linalg.inv(self._world_base) @ pose_matrix(t.slot.xyz,
                                                                          t.slot.rpy)
                       for t in tools}
        self._signals: dict[str, tuple[int, int]] = {}   # name -> (unit, bit)
        self._image: list[tuple[int, int]] = []   # (unit, mask) per ring I/O column
        self._payloads = {t.name: tool_payload(t) for t in tools}
        self._carried: tuple = (None, None)   # the tool on the flange, its part's payload

    # ---- the I/O image ----------------------------------------------------------------------

    def controller_started(self) -> None:
        """Learn the I/O map and have the cycle mirror the end effector's signals."""
        self._signals = {name: (unit.id, bit) for unit in self.link.proxy.io_map()
                         for bit, name in unit.bits}
        masks: dict[int, int] = {}
        for name, (unit, bit) in self._signals.items():
            if name.startswith(ID_PREFIX) or name == LOCK or any(
                    name in (f.output, f.confirm) for f in FUNCTIONS.values()):
                masks[unit] = masks.get(unit, 0) | 1 << bit
        self._image = sorted(masks.items())
        self.link.send({"op": "io_image", "units": self._image})
        self._carry(*self._carried)   # a fresh cycle knows no payload

    def changer_bits(self, unit: IoUnit) -> int:
        """The bits of `unit` that drive the tool changer (its lock)."""
        where = self._signals.get(LOCK)
        return 1 << where[1] if where is not None and where[0] == unit.id else 0

    def _bit(self, image: np.ndarray, name: str) -> bool | None:
        where = self._signals.get(name)
        if where is None:
            return None
        for column, (unit, mask) in enumerate(self._image):
            if unit == where[0] and mask >> where[1] & 1:
                value = image[column]
                return None if np.isnan(value) else bool(int(value) >> where[1] & 1)
        return None

    def _mounted_id(self, image: np.ndarray) -> int:
        tool_id = 0
        for name in self._signals:
            if name.startswith(ID_PREFIX) and self._bit(image, name):
                tool_id |= 1 << int(name[len(ID_PREFIX):])
        return tool_id

    # ---- state ------------------------------------------------------------------------------

    def state(self, image: np.ndarray | None = None) -> tuple[str, str]:
        """(tool on the flange or "", its state) from an I/O image (default: the newest)."""
        if image is None:
            image = self.link.sample().io
        tool_id = self._mounted_id(image)
        if tool_id == 0:
            return "", "none"
        tool = self._by_id.get(tool_id)
        if tool is None:
            return f"unknown tool {tool_id}", "unknown"
        functions = FUNCTIONS[tool.kind]
        on, confirmed = self._bit(image, functions.output), self._bit(image, functions.confirm)
        return tool.name, functions.states[0 if not on else 2 if confirmed else 1]

    def mounted(self) -> ToolSpec | None:
        return self._by_id.get(self._mounted_id(self.link.sample().io))

    # ---- seed 3.8.1 getTool / putTool -------------------------------------------------------

    def get_tool(self, name: str) -> str:
        tool = self._tool(name)
        mounted = self.mounted()
        if mounted is tool:
            return f"the {name} is on the flange already"
        if mounted is not None:
            raise WrongState(f"the {mounted.name} is on the flange: PutTool it first",
                             tool=mounted.name)
        slot = self._slots[name]
        approach, into, out = self._steps("GetTool", name, [
            ("approach", _above(slot, APPROACH), True), ("into the slot", slot, False),
            ("out of the rack", _above(slot, tool.length + CLEARANCE), False)],
            after=lambda scene, q: scene.mount_tool(name))
        self._write(FUNCTIONS[tool.kind].output, False)
        self._play("GetTool", *approach)
        self._play("GetTool", *into)
        self._write(LOCK, True)
        if not self._wait(lambda: self.mounted() is tool, COUPLE_TIMEOUT):
            self._write(LOCK, False)
            raise ControllerFailure(f"the tool changer did not report the {name} coupled "
                                    f"within {COUPLE_TIMEOUT:g} s; the lock is released")
        self.follow_changer()
        self._play("GetTool", *out)
        return f"the {name} is on the flange"

    def put_tool(self, name: str) -> str:
        tool = self._tool(name)
        mounted = self.mounted()
        if mounted is not tool:
            what = f"the {mounted.name} is" if mounted else "no tool is"
            raise WrongState(f"{what} on the flange, not the {name}", tool=name)
        slot = self._slots[name]
        above, into, away = self._steps("PutTool", name, [
            ("above the slot", _above(slot, tool.length + CLEARANCE), True),
            ("into the slot", slot, False), ("away", _above(slot, APPROACH), False)],
            after=lambda scene, q: _let_go(scene, q, unmount=True))
        self._play("PutTool", *above)
        self._play("PutTool", *into)
        self._switch(tool, False)
        self._write(LOCK, False)
        if not self._wait(lambda: self.mounted() is None, COUPLE_TIMEOUT):
            raise ControllerFailure(f"the tool changer still reports the {name} after "
                                    f"{COUPLE_TIMEOUT:g} s")
        self.follow_changer()
        self._play("PutTool", *away)
        return f"the {name} is in the rack"

    # ---- the changer written directly (setDigitalIO) -----------------------------------------

    def check_changer(self, release: bool) -> None:
        """Before the changer's lock is written directly: it opens only with the tool in its
        rack slot (elsewhere it would drop it)."""
        mounted = self.mounted()
        if not release or mounted is None:
            return
        flange = self.kinematics.forward(self.link.sample().position)
        if np.linalg.norm(flange[:3, 3] - self._slots[mounted.name][:3, 3]) > SLOT_REACH:
            raise WrongState(f"the tool changer opens only with the {mounted.name} in its rack "
                             f"slot (PutTool takes it there)", tool=mounted.name)

    def follow_changer(self) -> None:
        """After the changer's lock was written: the tool offset and the collision scene
        follow the tool the changer reports (the tool's tip, or the flange)."""
        self._wait_cycles(2)
        mounted, scene = self.mounted(), self.collisions
        if scene.mounted is not None and (mounted is None or mounted.name != scene.mounted):
            _let_go(scene, self.link.sample().position, unmount=True)
            self._set_tool_offset(np.eye(4))
        if mounted is not None and scene.mounted is None:
            scene.mount_tool(mounted.name)
            self._set_tool_offset(_along_z(mounted.length))
        if mounted is not self._carried[0]:
            self._carry(mounted)

    # ---- seed 3.8.1 activateTool / deactivateTool -------------------------------------------

    def activate(self, name: str, bits: int) -> str:
        tool, _ = self._functions(name, bits)
        return self._switch(tool, True)

    def deactivate(self, name: str, bits: int) -> str:
        tool, _ = self._functions(name, bits)
        return self._switch(tool, False)

    def _switch(self, tool: ToolSpec, on: bool) -> str:
        """The tool's function on or off, once done; the collision scene follows (a part taken
        moves with the tool, a part let go lies where it is)."""
        self._write(FUNCTIONS[tool.kind].output, on)
        gripper = tool.kind == "parallel_gripper"
        if gripper and on and not self._wait(lambda: self.state()[1] == "closed", CLOSE_TIMEOUT):
            raise ControllerFailure(f"the {tool.name} did not report closed within "
                                    f"{CLOSE_TIMEOUT:g} s")
        # A gripper opens in its rated time (no input says it is open); suction acts at once.
        self._wait_cycles(tool.stroke / 2 / tool.finger_speed / self.link.cycle_time
                          if gripper and not on else 2)
        held = self._follow_in_scene(tool, on)
        if gripper:
            return "closed" + (f" on {held}" if held else "") if on else "open"
        if not on:
            return "suction off"
        return f"suction on, holding {held}" if held else "suction on, no part held"

    def _follow_in_scene(self, tool: ToolSpec, on: bool) -> str | None:
        """Tell the collision scene what the tool took or let go; the part taken, if any."""
        scene = self.collisions
        q = self.link.sample().position
        if not on:
            if scene.held is not None:
                _let_go(scene, q)
                self._carry(tool)
                if self.world is not None:   # where it lands, not where it was let go
                    self.world.settle()
            if tool.kind == "parallel_gripper":
                scene.set_finger_gap(tool.stroke)
            return None
        holding = tool.kind == "parallel_gripper" or self.state()[1] == "holding"
        part = self._part_at_tip(q, tool) if holding else None
        if tool.kind == "parallel_gripper":   # closed on the part, or all the way
            scene.set_finger_gap(min(self._parts[part].size[:2]) if part else 0.0)
        if part is not None and scene.held is None:
            flange = self._world_base @ self.kinematics.forward(q)
            in_flange = np.linalg.inv(flange) @ self.collisions.part_pose(part)
            scene.allow(scene.grasp(part))
            scene.attach_part(part, q)
            self._carry(tool, part_payload(self._parts[part], in_flange))
        return part

    def _carry(self, tool: ToolSpec | None, part: np.ndarray | None = None) -> None:
        """Tell the cycle what the flange carries: `tool` and the part it holds (its dynamic
        parameters, arm_dynamics.py), if any."""
        self._carried = (tool, part)
        payload = np.array(NO_PAYLOAD) if tool is None else self._payloads[tool.name]
        if part is not None:
            payload = payload + part
        self.link.send({"op": "payload", "parameters": tuple(payload.tolist())})

    def _part_at_tip(self, q: np.ndarray, tool: ToolSpec) -> str | None:
        """The part of the collision scene whose centre is nearest the tool's tip, within
        GRASP_REACH of it (what the tool just took), if any."""
        tip = (self._world_base @ self.kinematics.forward(q) @ _along_z(tool.length))
        nearest, best = None, GRASP_REACH
        for name in self._parts:
            pose = self.collisions.part_pose(name)
            if pose is not None and (d := float(np.linalg.norm(pose[:3, 3] - tip[:3, 3]))) < best:
                nearest, best = name, d
        return nearest

    def _functions(self, name: str, bits: int) -> tuple[ToolSpec, Functions]:
        tool = self._tool(name)
        if self.mounted() is not tool:
            raise WrongState(f"the {name} is not on the flange", tool=name)
        if bits != 1:
            raise OutOfRange(f"the {name} ({tool.kind}) has one function, bit 0 (value 1); "
                             f"got bit field {bits:#x}")
        return tool, FUNCTIONS[tool.kind]

    # ---- helpers ----------------------------------------------------------------------------

    def _tool(self, name: str) -> ToolSpec:
        tool = self.tools.get(name)
        if tool is None:
            raise ParamError(f"no tool {name!r} in the rack (tools: {', '.join(self.tools)})")
        return tool

    def _write(self, signal: str, on: bool) -> None:
        where = self._signals.get(signal)
        if where is None:
            raise ControllerFailure(f"the cell has no I/O signal {signal!r}")
        unit, bit = where
        status = self.link.proxy.write_io_unit(unit, 1 << bit if on else 0,
                                                      0 if on else 1 << bit)
        if status is not Status.OK:
            raise ControllerFailure(f"the controller refused to set {signal} to {int(on)}")

    def _steps(self, command: str, tool: str, steps, after) -> list[tuple]:
        """Plan the moves of a tool change, each from where the one before ends, and check
        them all before any runs: (step, flange goal (4x4 in base_link), joint move?). The
        last one is checked against what `after(scene, q)` makes of a copy of the scene (the
        coupling or uncoupling made, from the joints q it starts at). The fine moves into and
        out of the slot stay in the tool's docking corridor, where the flange may meet the
        tool and the tool its rack (collision/docking.py). Returns (step, trajectory)."""
        motions = self.motions
        planner, settings = motions.planner, self.settings.current
        model = self.collisions.model()
        q, out = motions.planning_start(), []
        for k, (step, flange_goal, joint) in enumerate(steps):
            if k == len(steps) - 1:
                changed = self.collisions.copy()
                after(changed, q)
                model = changed.model()
            if joint:
                trajectory = planner.joint_move(q, planner.pose_goal_joints(q, flange_goal),
                                                planner.limits(settings, None))
            else:
                limits = planner.limits(settings, min(settings.speed_percent, TOOL_CHANGE_SPEED))
                trajectory = planner.straight_move(q, flange_goal, limits, np.eye(4))
            step = f"{tool}: {step}"
            motions.check_collisions([trajectory], f"{command} {step}", model=model)
            out.append((step, trajectory))
            q = trajectory.positions[-1]
        return out

    def _play(self, command: str, step: str, trajectory) -> None:
        """One step of a tool change, planned by _steps."""
        motion = self.motions.play(command, step, trajectory, trajectory.duration + 10.0)
        if motion.phase != "done":
            why = motion.report.get("message", "")
            raise ControllerFailure(f"{command} stopped at the step '{step}' ({motion.phase}"
                                    f"{': ' + why if why else ''}); the arm stays there",
                                    step=step)

    def _set_tool_offset(self, offset: np.ndarray) -> None:
        self.settings.update(lambda s: s.with_tool_offset(offset))

    def _wait(self, done, timeout: float) -> bool:
        """Until done(), for at most `timeout` s of controller time (and a little more of wall
        time, should the controller stop)."""
        link = self.link
        end = link.feedback.head + timeout / link.cycle_time
        give_up = time.monotonic() + timeout + 5.0
        while not done():
            if link.feedback.head > end or time.monotonic() > give_up:
                return False
            time.sleep(0.001)
        return True

    def _wait_cycles(self, cycles: float) -> None:
        self._wait(lambda: False, cycles * self.link.cycle_time)


def _along_z(length: float) -> np.ndarray:
    return pose_matrix((0.0, 0.0, length), (0.0, 0.0, 0.0))


def _above(slot: np.ndarray, height: float) -> np.ndarray:
    """The slot pose moved `height` against its z (tools hang down: up, away from the rack)."""
    return slot @ _along_z(-height)


def _let_go(scene, q: np.ndarray, unmount: bool = False) -> None:
    """The collision scene after the tool let its part go at joints q (and, unmount, after
    the changer let the tool go)."""
    if scene.held is not None:
        scene.forbid(f"grasp {scene.held}")
        scene.release_part(q)
    if unmount:
        scene.unmount_tool()
