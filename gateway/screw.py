"""MoveScrew's helix (spec VII) as path points, computed off the connection's event loop.

The screw turns the tool rigidly about an axis (through a point, parallel to the tool's Z)
while it advances along it. The path has a point every SCREW_STEP of turn and every
SCREW_STEP_LENGTH of travel, at most MAX_SCREW_POINTS: a screw that needs more is refused
before anything is computed, so one command cannot take the gateway's time (or the device's
planner's) with it. The points are computed on a worker thread (2,000 take about 35 ms): the
loop that answers every connection's GetStatus never waits behind them (bench_crcl.py).
"""
from __future__ import annotations

import asyncio
import functools
import math

import numpy as np
import pinocchio as pin

from landscape.gateway.errors import CrclError

SCREW_STEP = math.radians(5.0)   # rad of turn between helix points, at most
SCREW_STEP_LENGTH = 0.005        # m of travel (around and along the axis) between them
# Every screw a TX90 can follow fits: its sixth joint turns 1.5 turns at most (some 110 points
# by angle), and a helix within its 1.05 m reach is under 10 m long (2,000 points by length).
MAX_SCREW_POINTS = 2_000


def point_count(turn: float, advance: float, radius: float) -> int:
    """Points of a helix turning `turn` rad and advancing `advance` m at `radius` m from its
    axis; CrclError past MAX_SCREW_POINTS."""
    steps = max(1, math.ceil(max(abs(turn) / SCREW_STEP,
                                 math.hypot(abs(turn) * radius, abs(advance)) / SCREW_STEP_LENGTH)))
    if steps > MAX_SCREW_POINTS:
        raise CrclError(f"the screw needs {steps} path points (one per {math.degrees(SCREW_STEP):g}"
                        f" degrees and {SCREW_STEP_LENGTH * 1000:g} mm); at most "
                        f"{MAX_SCREW_POINTS} are made: send it as several shorter screws")
    return steps


def helix(start: np.ndarray, center: np.ndarray, axis: np.ndarray, turn: float,
          advance: float, steps: int) -> list[list[float]]:
    """`steps` SI poses x, y, z, roll, pitch, yaw: `start` (4x4, m) turned by `turn` rad about
    the unit `axis` through `center` (3,) and advanced `advance` m along it, in equal parts (the
    start itself not included). Plain floats: numpy's cost ten times as much in a request."""
    points = []
    for step in range(1, steps + 1):
        spin = pin.exp3(axis * turn * step / steps)
        position = center + spin @ (start[:3, 3] - center) + axis * advance * step / steps
        points.append([*position.tolist(), *pin.rpy.matrixToRpy(spin @ start[:3, :3]).tolist()])
    return points


async def helix_off_loop(*args) -> list[list[float]]:
    """`helix(*args)` on the loop's worker threads."""
    return await asyncio.get_running_loop().run_in_executor(None, functools.partial(helix, *args))
