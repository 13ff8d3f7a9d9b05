"""The clearance guard of a jog session: a jogging arm slows near the cell and stops at the
safety margin (issue 11), while it stays free to move away.

While a session runs, a thread of the server reads the arm's commanded joints from the feedback
ring every PERIOD_CYCLES cycles and measures its clearance in the collision scene as it is now
(collision.clearance: the arm with its tool and any held part, against the fixtures, the tools
in the rack, the parts and the floor). Within SLOW_ZONE of the margin it sends the cycle the
clearance's gradient in joint space (finite differences, m/rad) and the rate at which the arm
may still close it, (clearance - margin) / TAU: the approach slows in proportion to the room
left and stops at the margin; jog_integrator.py applies this every cycle. TAU is long beside the
guard's delay (a few cycles), so what the arm travels before the next figure arrives is a
small fraction of the room left. Beyond the zone it sends "no gradient" and the jog is free.
It sends every tick: figures that stop coming (this thread stalled) hold the arm in the cycle
(jog_integrator.STALE_CYCLES).
"""
from __future__ import annotations

import math
import threading
import numpy as np

from landscape.server.cycle.feedback import CMD
from landscape.server.device.motion_control import ENDED, MotionControl, RunningMotion
from landscape.server.link.controller_link import ControllerLink
from landscape.server.planning.collision import CollisionScene, clearance

SLOW_ZONE = 0.15       # m beyond the margin where the guard starts to act
TAU = 0.1              # s: the approach allowed is the room left over TAU
STEP = 1e-4            # rad, the finite differences' step
PERIOD_CYCLES = 2
HELD_WITHIN = 0.001    # m over the margin at which the reply says the arm is held


class JogGuard:
    def __init__(self, link: ControllerLink, motions: MotionControl, collisions: CollisionScene,
                 motion: RunningMotion):
        self.link, self.motions, self.collisions, self.motion = link, motions, collisions, motion
        self.held = ""         # why the arm does not go on, for the Jog stream's reply
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._run, daemon=True, name="jog-guard")
        self._thread.start()

    def close(self) -> None:
        """The guard stops after its present tick (no wait: the event loop calls this)."""
        self._stop.set()

    def _run(self) -> None:
        ring = self.link.feedback
        period = PERIOD_CYCLES * self.link.cycle_time
        while not self._stop.wait(period) and self.motion.phase not in ENDED:
            row = ring.row(ring.head)
            if row is None:
                continue
            gradient, rate = self._figures(np.array(row[CMD], dtype=float)) or (None, 0.0)
            self.motions.send({"op": "jog_clearance", "gradient": gradient, "rate": rate})

    def _figures(self, q: np.ndarray) -> tuple[np.ndarray, float] | None:
        """(gradient (6,) m/rad, approach rate allowed m/s) at joints q, or None out of reach."""
        scene = self.collisions
        model, margin = scene.model(), scene.margin
        limit = margin + SLOW_ZONE
        near = clearance(model, q, limit=limit)
        if math.isinf(near.distance):
            self.held = ""
            return None
        d = near.distance
        # Pairs beyond `limit` count as at `limit`: a step never makes the clearance jump.
        gradient = np.array([(min(clearance(model, q + STEP * e, limit=limit).distance, limit)
                              - d) / STEP for e in np.eye(6)])
        room = max(0.0, d - margin)
        self.held = (f"held at the {margin * 1000:g} mm safety margin: {d * 1000:.1f} mm between "
                     f"{' and '.join(near.bodies)}" if room < HELD_WITHIN else "")
        return gradient, room / TAU
