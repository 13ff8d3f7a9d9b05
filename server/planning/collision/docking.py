"""Docking: a tool coupled or put back at the changer, along its coupling's axis only.

A tool not on the flange (in its rack slot, or where the changer let it go) is coupled by
bringing the bare flange (link6) onto its plate straight along the plate's axis, which is
what a tool changer needs and what a client driving the arm itself does (CRCL: MoveTo above
the slot, MoveTo onto it, CloseToolChanger); a mounted tool is put back the same way, down
into its own rack slot, where it stands on the rack. So the bare flange may meet an unmounted
tool, and a mounted tool the fixtures its own slot stands on, while the flange is in that
tool's (or that slot's) corridor: its origin within the changer's capture distance (the
cell's lock_distance) of the plate's axis, from DEPTH above the plate to lock_distance into
it, and its orientation within lock_angle of the plate's. Anywhere else those contacts are
like any other: a swipe from the side, a tilted approach, sliding out sideways. Nothing else
is allowed there: link5 and the other links stay checked against the tool, the mounted tool
against the other tools in the rack.

Frames: base_link; the plate's z points along the tool, away from the flange (the approach
comes from its -z side, as tooling.py's approach point does).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from landscape.server.planning.motion.constraints import rotation_angle

DEPTH = 0.1     # m above the plate where a corridor begins (tooling.APPROACH: far clear of it)


@dataclass(frozen=True, eq=False)
class Dock:
    """A corridor where the moving body `a` may meet body `b`: plate (4, 4) the tool's plate
    frame when docked, in base_link; radius (m) and angle (rad): the changer's capture
    tolerances."""

    a: str
    b: str
    plate: np.ndarray
    radius: float
    angle: float

    def inside(self, flange: np.ndarray) -> np.ndarray:
        """(N,) bool: which flange frames (N, 4, 4, base_link) are in the corridor."""
        rel = np.linalg.inv(self.plate) @ flange
        p = rel[:, :3, 3]
        turned = rotation_angle(np.eye(3), rel[:, :3, :3])
        return ((np.hypot(p[:, 0], p[:, 1]) <= self.radius) & (p[:, 2] >= -DEPTH)
                & (p[:, 2] <= self.radius) & (turned <= self.angle))


def strict_stretches(inside: np.ndarray, first: int) -> list[tuple[int, int]]:
    """The stretches (first sample, last sample) of samples first .. first + len(inside) - 1
    where a corridor's contact is not allowed: every sample outside the corridor and every
    step between two samples that are not both inside (the arm moves linearly in joint space
    between samples: a step entering or leaving the corridor is checked whole)."""
    if len(inside) == 1:
        return [] if inside[0] else [(first, first)]
    strict = np.concatenate([[False], ~(inside[:-1] & inside[1:]), [False]])
    edges = np.flatnonzero(np.diff(strict.astype(np.int8)))    # steps [a, b) are strict
    return [(first + int(a), first + int(b)) for a, b in zip(edges[::2], edges[1::2])]
