"""The collision scene follows the parts where the world has them (issue 11).

The scene learns tool changes and grasps from what the device commands (tooling.py), but
parts also move without a command: a person puts one down or takes one away (the operator
panel), a part let go above the table falls, the arm pushes one. So before a motion is checked
the scene takes every part's pose from the world (the simulator, read between two cycles, as a
camera would see the cell), and after the tool lets a part go the device waits for it to come
to rest there. A part the scene has in the tool that the world's tool no longer holds is let
go in the scene too. Poses that moved less than MOVED / TURNED are left alone (a new pose
recompiles the scene's model).
"""
from __future__ import annotations

import logging
import time
from typing import TYPE_CHECKING

import numpy as np
from scipy.spatial.transform import Rotation

from landscape.server.collision import CollisionModelError
from landscape.sim.clock import CycleProcessError
from landscape.sim.world import read_part_states

if TYPE_CHECKING:
    from landscape.server.device import Device

log = logging.getLogger(__name__)

MOVED = 0.001           # m
TURNED = 0.01           # rad
AT_REST = 0.002         # m/s: a part slower than this has landed
SETTLE_TIMEOUT = 1.0    # s of controller time a part let go may take to land


class WorldParts:
    def __init__(self, device: "Device"):
        self.device = device

    def _read(self) -> dict | None:
        try:
            return self.device.link.between_cycles(read_part_states)
        except (CycleProcessError, TimeoutError) as error:
            log.warning("the part poses could not be read (%s): the collision scene keeps "
                        "its own", error)
            return None

    def refresh(self, states: dict | None = None) -> None:
        """Every part of the scene where the world has it now (or as `states` read it)."""
        states = states or self._read()
        if states is None:
            return
        scene = self.device.collisions
        for name, (xyz, quaternion, _, held) in states.items():
            if name == scene.held:
                if held:
                    continue
                try:                       # the tool dropped it, or a person took it
                    scene.forbid(f"grasp {name}")
                except CollisionModelError:
                    pass
            pose = np.eye(4)
            pose[:3, :3] = Rotation.from_quat(quaternion).as_matrix()
            pose[:3, 3] = xyz
            now = scene.part_pose(name)
            if now is None or not _close(now, pose) or name == scene.held:
                scene.place_part(name, pose)

    def settle(self) -> None:
        """Wait until no loose part moves (at most SETTLE_TIMEOUT of controller time: a part
        let go lands), then refresh."""
        link = self.device.link
        end = link.feedback.head + SETTLE_TIMEOUT / link.cycle_time
        give_up = time.monotonic() + SETTLE_TIMEOUT + 5.0
        while True:
            states = self._read()
            if (states is None or all(s[2] < AT_REST for s in states.values() if not s[3])
                    or link.feedback.head > end or time.monotonic() > give_up):
                break
            time.sleep(0.005)
        self.refresh(states)


def _close(a: np.ndarray, b: np.ndarray) -> bool:
    turned = Rotation.from_matrix(a[:3, :3].T @ b[:3, :3]).magnitude()
    return bool(np.linalg.norm(a[:3, 3] - b[:3, 3]) < MOVED and turned < TURNED)
