"""The simulated CS8 on pybullet (DIRECT mode, a client of its own): the LLI's side of cs8.py over
the arm's physics (bullet_drives.py) and the cell's world (world.py: fixtures, tools, parts).

Besides what every simulated CS8 offers, `world` (the pybullet world) and what it makes
possible: part tracking (`part_states`), parts put down and taken away by hand (the panel's
place_part, remove_part), and sensors that measure the world (sensors.py).

Single-threaded: call everything from the thread that steps (the cycle process).
"""
from __future__ import annotations

from landscape.robot.cell import Cell
from landscape.robot.controller import Capability, CyclicFunction
from landscape.sim.bullet_drives import Drives, connect
from landscape.sim.cs8 import SimulatedCS8
from landscape.sim.sensors import SENSOR_CLASSES
from landscape.sim.world import World


class BulletController(SimulatedCS8):
    """The CS8 of `cell` on pybullet; `cyclic` is called at the end of every `step()`."""

    def __init__(self, cell: Cell, cyclic: CyclicFunction | None = None):
        spec = cell.controller
        self._bc = connect(spec.cycle_time, spec.substeps)
        self.world = World(self._bc, cell)
        sensors = {s.name: SENSOR_CLASSES[s.kind](self.world, s) for s in cell.sensors}
        super().__init__(cell, Drives(self._bc, self.world, cell.arm, spec), sensors,
                         self.world, cyclic)

    def _advance(self) -> None:
        self._drives.cycle()
        self.world.update()

    def _read_world(self, wire: str) -> bool:
        return self.world.read_input(wire)

    def _write_world(self, wire: str, value: bool) -> None:
        self.world.set_output(wire, value)

    def _disconnect(self) -> None:
        self._bc.disconnect()

    def capabilities(self) -> frozenset[Capability]:
        return frozenset({Capability.PANEL, Capability.WORLD, Capability.SENSING})

    def part_states(self) -> dict[str, tuple]:
        return self.world.part_states()
