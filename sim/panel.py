"""What a person does in the cell: the e-stop button, the door, parts moved by hand.

These inputs are not outputs anyone could write; tests and the dashboard operate them here
(`SimulatedCS8.panel`, and its operate_panel: the controller interface's PANEL capability).
The e-stop acts at once: `on_estop(pressed)` lets the controller cut the drives in the same
call, not a cycle later. The door is only an input (door_closed): what an open door means is
the supervisor's policy. Parts are put down and taken away in `world` (a pybullet World; a
cell without one has no parts to move).
"""
from __future__ import annotations

from typing import TYPE_CHECKING, Callable

if TYPE_CHECKING:   # pybullet only where a world is simulated
    from landscape.sim.world import World


class Panel:
    def __init__(self, world: World | None, on_estop: Callable[[bool], None]):
        self._world = world
        self._on_estop = on_estop
        self.estop_pressed = False
        self.door_closed = True

    def press_estop(self) -> None:
        if not self.estop_pressed:
            self.estop_pressed = True
            self._on_estop(True)

    def release_estop(self) -> None:
        if self.estop_pressed:
            self.estop_pressed = False
            self._on_estop(False)

    def open_door(self) -> None:
        self.door_closed = False

    def close_door(self) -> None:
        self.door_closed = True

    def read(self, wire: str) -> bool:
        """The panel's wires: "estop" (1 while pressed), "door_closed"."""
        return self.estop_pressed if wire == "estop" else self.door_closed

    def place_part(self, name: str, xyz, rpy=(0.0, 0.0, 0.0)) -> None:
        """Put part `name` down at xyz (m), fixed-axis angles rpy (rad)."""
        self._in_world().place_part(name, xyz, rpy)

    def remove_part(self, name: str) -> None:
        """Take part `name` out of the cell (down on the floor, out of reach)."""
        self._in_world().remove_part(name)

    def _in_world(self) -> World:
        if self._world is None:
            raise RuntimeError("this cell's controller has no world to move parts in")
        return self._world

