"""The cell around the arm, as the device's commands reach it: sensors, guarded and compliant
motion, tools, digital I/O, manual control and the vendor hook (seed 3.7, 3.8, 4).

`build_workcell` makes the parts for a device and its cell file and wires them to the device:
what each does once the controller has (re)started, and which cycle reports each takes.
"""
from __future__ import annotations

from dataclasses import dataclass

from landscape.server.device.device import Device
from landscape.server.workcell.digital_io import DigitalIO
from landscape.server.workcell.guarded import GuardedMotion
from landscape.server.workcell.jog import ManualControl
from landscape.server.workcell.sensing import Sensors
from landscape.server.workcell.tooling import Tooling
from landscape.server.workcell.vendor import VendorCommands
from landscape.robot.cell import Cell


@dataclass(frozen=True)
class Workcell:
    sensors: Sensors
    guarded: GuardedMotion
    tools: Tooling
    io: DigitalIO
    manual: ManualControl
    vendor: VendorCommands


def build_workcell(device: Device, cell: Cell) -> Workcell:
    sensors = Sensors(device)
    tools = Tooling(device, cell.world.tools, cell.world.parts, cell.base)
    io = DigitalIO(device, tools)
    device.on_controller_start.extend([sensors.controller_started, tools.controller_started,
                                       io.controller_started])
    device.report_handlers.update({"io_signal": io.on_report, "io_timeout": io.on_report})
    return Workcell(sensors, GuardedMotion(device, sensors), tools, io, ManualControl(device),
                    VendorCommands(device, sensors, cell.recorder.path))
