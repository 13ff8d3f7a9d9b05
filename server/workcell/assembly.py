"""The cell around the arm, as the device's commands reach it: sensors, guarded and compliant
motion, tools, digital I/O, manual control and the vendor hook (seed 3.7, 3.8, 4).

`build_workcell` makes the parts for a device and its cell file, each given the parts of the
device it uses (never the Device itself), and wires them to the device: what each does once
the controller has (re)started, and which cycle reports each takes.
"""
from __future__ import annotations

from dataclasses import dataclass

from landscape.robot.cell import Cell
from landscape.robot.controller import Capability
from landscape.server.device.device import Device
from landscape.server.workcell.digital_io import DigitalIO
from landscape.server.workcell.guarded import GuardedMotion
from landscape.server.workcell.jog import ManualControl
from landscape.server.workcell.sensing import Sensors
from landscape.server.workcell.tooling import Tooling
from landscape.server.workcell.vendor import VendorCommands
from landscape.server.workcell.world_parts import WorldParts


@dataclass(frozen=True)
class Workcell:
    sensors: Sensors
    guarded: GuardedMotion
    tools: Tooling
    io: DigitalIO
    manual: ManualControl
    vendor: VendorCommands
    world: WorldParts | None    # the collision scene's loose parts follow the world's

    def close(self) -> None:
        if self.world is not None:
            self.world.close()


def build_workcell(device: Device, cell: Cell) -> Workcell:
    link, motions, state = device.link, device.motions, device.state_machine
    settings, collisions = device.settings_keeper, device.collisions
    world = WorldParts(link, collisions) if Capability.WORLD in link.capabilities else None
    sensors = Sensors(link, settings)
    tools = Tooling(link, motions, device.kinematics, collisions, settings, world,
                    cell.world.tools, cell.world.parts, cell.base)
    io = DigitalIO(link, motions, state, device.bus, device.rsvp, tools)
    device.on_controller_start.extend([sensors.controller_started, tools.controller_started,
                                       io.controller_started])
    device.report_handlers.update({"io_signal": io.on_report, "io_timeout": io.on_report})
    guarded = GuardedMotion(motions, state, sensors, device.kinematics, collisions, settings,
                            device.arm, link.cycle_time, device.power.fault)
    manual = ManualControl(state, motions, link, collisions, settings, device.arm)
    vendor = VendorCommands(link, state, sensors, cell.recorder.path)
    return Workcell(sensors, guarded, tools, io, manual, vendor, world)
