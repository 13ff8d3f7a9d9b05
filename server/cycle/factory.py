"""The controller the cycle steps, built where the cycle runs (the cycle process, or the
lock-step thread): the cell file's backend (robot/backends.py) with the device's Executor as
its cyclic function. The server names this function (ControllerLink); only the process that
runs it imports the backend.
"""
from __future__ import annotations

from landscape.robot import controller as interface
from landscape.robot.backends import backend
from landscape.robot.cell import load_cell
from landscape.robot.controller import Capability
from landscape.server.cycle.executor import Executor
from landscape.server.cycle.feedback import FeedbackRing
from landscape.server.cycle.process import Mailbox

# What the server runs between cycles (interface.operate_panel, interface.read_part_states) is
# loaded before the loop starts: an import on the loop's thread would hold a cycle up.
assert interface.operate_panel and interface.read_part_states


def build_controller(cell_path: str | None, ring: FeedbackRing, mailbox: Mailbox,
                     estop_pressed: bool = False, backend_name: str | None = None):
    """The cell's controller with the Executor as cyclic function. `estop_pressed`: the cell's
    e-stop button is down (a latch outside the controller: a controller started afresh finds
    it as it was left). `backend_name`: another backend than the cell file's."""
    from landscape.server.cycle.arm_dynamics import base_gravity   # pinocchio: only here
    cell = load_cell(cell_path)
    make = backend(backend_name or cell.controller.backend)
    controller = make(cell, Executor(mailbox, cell.controller.cycle_time, ring, cell.arm,
                                     base_gravity(cell)))
    if estop_pressed and Capability.PANEL in controller.capabilities():
        controller.operate_panel("press_estop")
    return controller
