"""What the server reads of the simulated world between two cycles (ControllerLink.between_cycles
runs a top-level function there, pickled by its module and name). This module imports nothing,
so the server can name the function without loading pybullet, and the cycle process loads
nothing heavy the first time it is called."""
from __future__ import annotations


def read_part_states(controller) -> dict[str, tuple]:
    """The parts of the controller's world (World.part_states): name -> (position (3,) m,
    quaternion xyzw, speed m/s, held by the mounted tool)."""
    return controller.world.part_states()
