"""Helpers for the tests of the simulated CS8: a setpoint-following cyclic function, joint moves,
and the tool-changer sequence. Real pybullet behind the controller, stepped in a plain loop (no
clock); the tests themselves never import pybullet."""
from __future__ import annotations

import dataclasses
import math
from collections import deque

import numpy as np

from landscape.sim.bullet_controller import BulletController
from landscape.robot.cell import Cell, load_cell
from landscape.robot.controller import EnableState, JointCmd
from landscape.robot.kinematics import Config, ReversingResult

DEFAULT_CELL = load_cell()


class Follower:
    """Cyclic function: commands queued setpoints, one per cycle, then holds the last one.
    While the drives are not enabled it commands the measured position; once enabled it holds
    the position it found (feeding the measurement back for ever would let the arm creep under
    gravity by the servo's tiny steady-state error, cycle after cycle). `errors` collects the
    following error reported by get() each cycle while moving."""

    def __init__(self):
        self.plan: deque = deque()
        self.last: np.ndarray | None = None
        self.fbk = None
        self.errors: list[np.ndarray] = []
        self.commands: list[np.ndarray] = []
        self.measured: list[np.ndarray] = []
        self.inject: JointCmd | None = None

    def __call__(self, ctrl: BulletController) -> bool:
        self.fbk = ctrl.get()
        if self.plan:
            self.errors.append(self.fbk.pos_err)
            self.measured.append(self.fbk.pos)
        if self.inject is not None:
            cmd, self.inject = self.inject, None
            ctrl.set(cmd)
            return True
        if self.plan:
            pos, vel = self.plan.popleft()
            self.last = pos
        elif ctrl.state().enable is EnableState.ENABLED:
            if self.last is None:
                self.last = self.fbk.pos
            pos, vel = self.last, np.zeros(6)
        else:
            pos, vel = self.fbk.pos, np.zeros(6)
            self.last = None
        self.commands.append(pos)
        ctrl.set(JointCmd(pos, vel))
        return True

    def start(self) -> np.ndarray:
        return self.plan[-1][0] if self.plan else (self.last if self.last is not None
                                                   else self.fbk.pos)

    def move(self, target, duration: float, cycle_time: float) -> None:
        """Queue a rest-to-rest quintic move to `target` (rad) taking `duration` s."""
        q0 = self.start()
        delta = np.asarray(target, dtype=float) - q0
        n = max(1, math.ceil(duration / cycle_time))
        for k in range(1, n + 1):
            t = k / n
            s = t ** 3 * (10 - 15 * t + 6 * t * t)
            ds = 30 * t * t * (1 - 2 * t + t * t) / (n * cycle_time)
            self.plan.append((q0 + s * delta, ds * delta))


def controller(cell: Cell | None = None, *, enabled: bool = True, **controller_overrides):
    """A BulletController with a Follower, initialised, enabled unless told otherwise; the events
    it raised are in `ctrl.events`."""
    cell = cell or DEFAULT_CELL
    if controller_overrides:
        cell = dataclasses.replace(
            cell, controller=dataclasses.replace(cell.controller, **controller_overrides))
    follower = Follower()
    ctrl = BulletController(cell, follower)
    ctrl.follower = follower
    ctrl.events = []
    ctrl.plug_event_func(ctrl.events.append)
    ctrl.step()
    if enabled:
        assert ctrl.init() == 0
        assert ctrl.enable() == 0
        run_until(ctrl, lambda: ctrl.state().enable is EnableState.ENABLED, 1.0)
    return ctrl


def run_until(ctrl, predicate, timeout_s: float) -> None:
    for _ in range(math.ceil(timeout_s / ctrl.cycle_time)):
        if predicate():
            return
        ctrl.step()
    assert predicate(), "timed out"


def run(ctrl, seconds: float) -> None:
    for _ in range(round(seconds / ctrl.cycle_time)):
        ctrl.step()


def move_to(ctrl, q, duration: float = 1.0, settle: float = 0.05) -> None:
    ctrl.follower.move(q, duration, ctrl.cycle_time)
    run_until(ctrl, lambda: not ctrl.follower.plan, duration + 1.0)
    run(ctrl, settle)


def matrix(pos, orn) -> np.ndarray:
    """4x4 pose from a position (3,) and a quaternion (x, y, z, w), as the world reports them."""
    x, y, z, w = orn
    t = np.eye(4)
    t[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                 [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                 [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    t[:3, 3] = pos
    return t


def joints_for(ctrl, world_pose: np.ndarray, near=None) -> np.ndarray:
    """Joints putting the flange at `world_pose` (4x4 in the world), nearest `near`."""
    base = ctrl.world.base_matrix()
    near = ctrl.follower.start() if near is None else near
    q, result = ctrl.reverse_kin(near, np.linalg.inv(base) @ world_pose, Config())
    assert result is ReversingResult.OK, result
    return q


def lifted(pose: np.ndarray, dz: float) -> np.ndarray:
    out = pose.copy()
    out[2, 3] += dz
    return out


def mount_tool(ctrl, name: str, duration: float = 1.5) -> None:
    """The tool-changer sequence: over the slot, down onto the plate, lock, lift well clear of
    the rack (the other tool stands next to it)."""
    tool = ctrl.world.tools[name]
    slot = matrix(*tool.plate_pose())
    move_to(ctrl, joints_for(ctrl, lifted(slot, 0.1)), duration)
    move_to(ctrl, joints_for(ctrl, slot), 0.8)
    ctrl.dio.write("toolchanger_lock", True)
    run(ctrl, 0.05)
    assert ctrl.world.mounted is tool
    move_to(ctrl, joints_for(ctrl, lifted(slot, 0.3)), 1.0)


def tip_position(ctrl, q, tool_length: float) -> np.ndarray:
    """Tool tip (m, base frame) for joints q: the flange moved `tool_length` along its z."""
    flange, _ = ctrl.forward_kin(q)
    return flange[:3, 3] + tool_length * flange[:3, 2]
