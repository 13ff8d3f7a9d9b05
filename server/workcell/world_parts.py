"""The collision scene follows the parts where the world has them (issue 11).

The scene learns tool changes and grasps from what the device commands (tooling.py), but
parts also move without a command: a person puts one down or takes one away (the operator
panel), a part let go above the table falls, the arm pushes one. So a thread reads every
part's pose from the world (the simulator, between two cycles, as a camera watching the cell
would) every PERIOD and the scene takes the poses of the parts lying loose; after the tool lets
a part go, the device waits for it to land and the scene takes where it lies. A part in the
tool is the tool's business (attach and release, tooling.py). A read of the world during
a change of the scene is dropped (the next one is newer), so the thread never undoes what the
device just told the scene. The read waits for the end of a cycle (4 ms on the real-time
clock), which is why it is not made before each motion: that would add it to every start.
"""
from __future__ import annotations

import logging
import threading
import time
import numpy as np
import pinocchio as pin

from landscape.robot.controller import read_part_states
from landscape.server.link.clock import CycleProcessError
from landscape.server.link.controller_link import ControllerLink
from landscape.server.planning.collision import CollisionScene

log = logging.getLogger(__name__)

PERIOD = 0.1            # s between two reads of the world
AT_REST = 0.002         # m/s: a part slower than this has landed
SETTLE_TIMEOUT = 1.0    # s of controller time a part let go may take to land


class WorldParts:
    def __init__(self, link: ControllerLink, collisions: CollisionScene):
        self.link, self.collisions = link, collisions
        self._unread = False    # the last read failed (said once, not every PERIOD)
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="world-parts")
        self._thread.start()

    def close(self) -> None:
        """The thread stops after its present read (no wait: a hung controller would hold it
        up to the call's timeout)."""
        self._stop.set()

    def _run(self) -> None:
        while not self._stop.wait(PERIOD):
            self.refresh()

    def refresh(self) -> dict | None:
        """The scene's loose parts where the world has them now; the states read (name: (xyz,
        quaternion xyzw, speed m/s, held)), None if the world could not be read or the scene
        changed meanwhile (nothing taken)."""
        scene = self.collisions
        version = scene.version
        try:
            states = self.link.between_cycles(read_part_states)
        except (CycleProcessError, TimeoutError) as error:
            if not self._unread:
                log.warning("the part poses cannot be read (%s): the collision scene keeps "
                            "its own until they can", error)
            self._unread = True
            return None
        self._unread = False
        poses = {}
        for name, (xyz, quaternion, _, held) in states.items():
            if not held:
                poses[name] = np.eye(4)
                poses[name][:3, :3] = pin.Quaternion(np.array(quaternion)).normalized().matrix()
                poses[name][:3, 3] = xyz
        return states if scene.follow_parts(poses, version) else None

    def settle(self) -> None:
        """Wait until no loose part moves (a part let go lands; at most SETTLE_TIMEOUT of
        controller time), the scene taking their poses."""
        link = self.link
        end = link.feedback.head + SETTLE_TIMEOUT / link.cycle_time
        give_up = time.monotonic() + SETTLE_TIMEOUT + 5.0
        while True:
            states = self.refresh()
            landed = states is not None and all(s[2] < AT_REST for s in states.values()
                                                if not s[3])
            if landed or self._unread or link.feedback.head > end \
                    or time.monotonic() > give_up:
                return
            time.sleep(0.005)
