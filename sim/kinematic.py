"""The kinematic backend: a simulated CS8 without physics. The arm is exactly where it was last
commanded; everything else is the CS8's as the pybullet backend has it (cs8.py): the LLI's
calls and power procedures, the command checks, the e-stop and the door, the cell's I/O units
by name and bit field, the recorder.

For fast runs (a program tried out, the device server's contract tests: `make test-fast`), and
the template a real CS8 driver copies: a `Controller` (robot/controller.py) built from the
parsed cell and the cyclic function, `step()` being the drive interrupt, and a row in the
backends' table (robot/backends.py). A driver for the real controller puts its LLI binding
where `KinematicDrives` stands (the drives: command, cycle, feedback, brakes) and its fieldbus
image where the world's wires read nothing here, and declares what it offers beyond the LLI
(`capabilities`).

What it does not offer (Capability): part tracking (no world: inputs wired to the world read
0, outputs wired to it act on nothing, so no tool couples) and sensors that measure anything
(a force/torque sensor reads zero, a range sensor nothing: NaN).
"""
from __future__ import annotations

import numpy as np

from landscape.robot.cell import Cell, SensorSpec
from landscape.robot.controller import Capability, CyclicFunction, JointFbk, SettleState
from landscape.sim.cs8 import SimulatedCS8


class KinematicDrives:
    """Drives that follow every command exactly: at the end of a cycle the joints are at the
    commanded position with the commanded velocity (rad, rad/s), the torque the feed-forward
    (N*m). Braked or holding, the joints stay where they are. The same surface as
    bullet_drives.Drives."""

    def __init__(self, cell: Cell):
        arm, spec = cell.arm, cell.controller
        self.effort = (spec.effort_factor * np.array(arm.max_effort)).tolist()
        self._zeros = [0.0] * 6
        self._hold = [float(q) for q in spec.initial_position]
        self.fbk = JointFbk(np.array(self._hold), np.zeros(6), np.zeros(6), np.zeros(6))
        self.settle = SettleState.SETTLED
        self.braked = True
        self._following = False
        self.command(self._hold, self._zeros, self._zeros)

    def command(self, pos: list, vel: list, tau: list) -> None:
        """Take a command (rad, rad/s, N*m; lists of 6 floats) as the one to follow."""
        self.cmd_pos, self.cmd_vel, self._tau = pos, vel, tau

    def cycle(self) -> None:
        if self._following:
            self._hold = self.cmd_pos
            self.fbk = JointFbk(np.array(self.cmd_pos), np.array(self.cmd_vel), np.zeros(6),
                                np.array(self._tau))
            moving = any(v != 0.0 for v in self.cmd_vel)
        else:
            self.fbk = JointFbk(np.array(self._hold), np.zeros(6), np.zeros(6), np.zeros(6))
            moving = False
        self.settle = SettleState.NOT_SETTLED if moving else SettleState.SETTLED

    def reference(self) -> tuple[list, list]:
        """The position and velocity aimed at: the command followed, else the held position."""
        return (self.cmd_pos, self.cmd_vel) if self._following else (self._hold, self._zeros)

    def brake(self) -> None:
        self.braked, self._following = True, False

    def power_on(self) -> None:
        self.hold()

    def hold(self) -> None:
        self.braked, self._following = False, False

    def engage(self, torque: bool, bumpless: bool = False) -> None:
        """Follow the commands from one to stay where the arm is (in torque mode too: with no
        dynamics, a torque moves nothing)."""
        self.command(list(self._hold), self._zeros, self._zeros)
        self.braked, self._following = False, True


class _Unmeasured:
    """A sensor with nothing to measure: a force/torque sensor reads zero, a range sensor
    nothing in range (NaN)."""

    def __init__(self, spec: SensorSpec):
        self._reading = np.zeros(6) if spec.kind == "force_torque" else np.array([np.nan])

    def read(self) -> np.ndarray:
        return self._reading.copy()

    def tare(self) -> None:
        pass


class KinematicController(SimulatedCS8):
    """The CS8 of `cell` without physics; `cyclic` is called at the end of every `step()`."""

    def __init__(self, cell: Cell, cyclic: CyclicFunction | None = None):
        sensors = {s.name: _Unmeasured(s) for s in cell.sensors}
        super().__init__(cell, KinematicDrives(cell), sensors, None, cyclic)

    def capabilities(self) -> frozenset[Capability]:
        return frozenset({Capability.PANEL})
