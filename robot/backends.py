"""The controller backends, found by name through one table (python-can's way).

The cell file names its backend (`[controller] backend`, robot/cell.py); the cycle process
builds it with `backend(name)(cell, cyclic)`: a `Controller` (controller.py) whose constructor
takes the parsed cell and the cyclic function, and which has `step()` and `cycle_time` for the
clocks. A backend's module is imported only when it is asked for, in the process that steps it:
the server never imports pybullet, and nothing above this table imports landscape.sim.

- "pybullet": the simulated CS8 on pybullet, with physics and a world (sim/bullet_controller.py)
- "kinematic": the simulated CS8 without physics, following its setpoints exactly
  (sim/kinematic.py): fast runs, and the template of a real CS8 driver

A real CS8 is one more row: its package, and the class that drives the controller.
"""
from __future__ import annotations

import importlib

from landscape.robot.controller import Controller

DEFAULT = "pybullet"
BACKENDS: dict[str, tuple[str, str]] = {
    "pybullet": ("landscape.sim.bullet_controller", "BulletController"),
    "kinematic": ("landscape.sim.kinematic", "KinematicController"),
}


def backend(name: str) -> type[Controller]:
    """The controller class of backend `name`, its module imported now; ValueError naming the
    backends there are for a name not in the table."""
    try:
        module, attribute = BACKENDS[name]
    except KeyError:
        raise ValueError(f"no controller backend {name!r} (backends: "
                         f"{', '.join(BACKENDS)})") from None
    return getattr(importlib.import_module(module), attribute)
