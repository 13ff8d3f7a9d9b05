"""The cell's world for the 3D view (table, rack, tools, parts, zones), read from the cell file.

TEMPORARY: no landscape.v1 call describes the cell's world yet, so the backend reads the same
cell file the device server was started with (the default cell unless told otherwise). This is
the one place the page learns something not from the device; it goes once the contract has a
call for it (e.g. DeviceService.GetCellDescription: fixtures, tool slots and parts as poses,
sizes and colours in the world frame, and the arm's base pose; live part poses in StateSample).
"""
from __future__ import annotations

import dataclasses

from landscape.sim.cell import load_cell


def world_description(cell_file: str | None) -> dict:
    """JSON-ready: lengths in meters, angles in radians (fixed-axis X-Y-Z roll, pitch, yaw),
    poses in the cell's world frame."""
    cell = load_cell(cell_file)
    return {
        "source": cell.source,
        "note": "read from the cell file by the dashboard backend: the contract has no call "
                "describing the world yet",
        "base": dataclasses.asdict(cell.base),
        "world": dataclasses.asdict(cell.world),
    }
