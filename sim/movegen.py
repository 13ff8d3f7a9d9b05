"""A simple joint movement generator: the LLI sample program's "Algo1", as a cyclic function.

For tests, benchmarks and bring-up; the device server's trajectory executor replaces it. It
uses only the synchronous calls `get()` and `set()`.

Messages (with a Mailbox, in a RealTimeClock's cycle process), plain dicts:
  parent -> cycle  {"op": "move", "target": [rad] * n, "duration": s, "id": any}
                   {"op": "where"}
  cycle -> parent  {"op": "done", "id": id, "position": [rad] * n}   when a move ended
                   {"op": "where", "position": [rad] * n, "command": [rad] * n, "moving": bool}
                   {"op": "error", "message": str}                     for a message it cannot use
"""
from __future__ import annotations

import math
from typing import Any

import numpy as np

from landscape.robot.controller import Controller, JointCmd


def quintic(tau: float) -> tuple[float, float]:
    """Rest-to-rest time law: s(tau) and ds/dtau for tau in [0, 1], with zero velocity and
    acceleration at both ends."""
    tau2 = tau * tau
    return tau2 * tau * (10.0 - 15.0 * tau + 6.0 * tau2), 30.0 * tau2 * (1.0 - 2.0 * tau + tau2)


class JointMove:
    """Cyclic function moving all joints from the last command to a target in a given time.

    Before its first move it commands the measured position with zero velocity, so it follows
    the arm and enabling never makes it jump; after a move it holds the target. Start a move
    only once the drives are enabled. cycle_time: s (the controller's). mailbox: optional
    `cycle_process.Mailbox` to take moves from the parent and report back (module docstring).
    """

    def __init__(self, cycle_time: float, mailbox: Any = None):
        self.cycle_time = float(cycle_time)
        self.mailbox = mailbox
        self._hold: np.ndarray | None = None   # commanded position when not moving, rad
        self._last: np.ndarray | None = None   # last commanded position, rad
        self._next: tuple | None = None        # requested move: (target, duration, id)
        self._move: tuple | None = None        # running move: (q0, delta, cycles, id)
        self._k = 0                            # cycles into the running move
        self.moves_done = 0

    @property
    def moving(self) -> bool:
        return self._move is not None or self._next is not None

    def start(self, target, duration: float, move_id: Any = None) -> None:
        """Move to `target` (rad, shape (n,)) in `duration` s, from the next cycle on, starting
        at the last command (a move started during another replaces it)."""
        if duration <= 0:
            raise ValueError("duration must be positive")
        self._next = (np.array(target, dtype=float), float(duration), move_id)

    def __call__(self, ctrl: Controller) -> bool:
        fbk = ctrl.get()
        if self.mailbox is not None:
            self._poll(fbk)
        if self._next is not None:
            target, duration, move_id = self._next
            self._next = None
            tracking = self._move is None and self._hold is None
            q0 = fbk.pos.copy() if tracking else self._last
            cycles = max(1, math.ceil(duration / self.cycle_time - 1e-9))
            self._move = (q0, target - q0, cycles, move_id)
            self._k = 0
        if self._move is None:
            pos = fbk.pos if self._hold is None else self._hold
            vel = np.zeros_like(pos)
        else:
            q0, delta, cycles, move_id = self._move
            self._k += 1
            s, ds = quintic(self._k / cycles)
            pos = q0 + s * delta
            vel = (ds / (cycles * self.cycle_time)) * delta
            if self._k >= cycles:
                self._hold = pos
                self._move = None
                self.moves_done += 1
                if self.mailbox is not None:
                    self.mailbox.post({"op": "done", "id": move_id, "position": pos.tolist()})
        self._last = pos
        ctrl.set(JointCmd(pos, vel))
        return True

    def _poll(self, fbk) -> None:
        while (msg := self.mailbox.poll()) is not None:
            op = msg.get("op") if isinstance(msg, dict) else None
            if op == "move":
                try:
                    self.start(msg["target"], msg["duration"], msg.get("id"))
                except (KeyError, TypeError, ValueError) as exc:
                    self.mailbox.post({"op": "error", "message": f"bad move: {exc!r}"})
            elif op == "where":
                command = fbk.pos if self._last is None else self._last
                self.mailbox.post({"op": "where", "position": fbk.pos.tolist(),
                                   "command": command.tolist(), "moving": self.moving})
            else:
                self.mailbox.post({"op": "error", "message": f"unknown message {msg!r}"})


def sample_controller(mailbox: Any = None, cell_path: str | None = None):
    """A `RealTimeClock` factory: the cell's `BulletController` (default cell if `cell_path` is
    None), initialised, with a `JointMove` taking its moves from `mailbox` as cyclic function.
    pybullet is imported and created where this runs (in the cycle process)."""
    from landscape.sim.bullet_controller import BulletController
    from landscape.robot.cell import load_cell

    cell = load_cell(cell_path)
    ctrl = BulletController(cell, JointMove(cell.controller.cycle_time, mailbox))
    ctrl.init()
    return ctrl
