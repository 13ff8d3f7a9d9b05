"""A snapshot of the cell compiled for checking: shapes, the pairs that may collide, the
pinocchio/coal models and the broad-phase bounds.

Why pinocchio's geometry model with coal: both ship with `pin` (no new dependency), pinocchio
reads the very URDFs the simulator loads (arm and tools), and coal gives exact signed distances
between the primitive shapes those URDFs use (cylinders, boxes, a half-space) in a few
microseconds, with witness points. What neither offers is a check of a whole trajectory with a
guarantee between samples; bounds.py and check.py add that on top (numpy broad phase over all
samples at once, then coal distances only where a bound is too close).

Pairs: every moving shape against every fixed one and against every moving shape of another
body, except shapes on the same link (rigid together: a mounted tool, its held part and link6),
adjacent arm links (they meet at their joint), and arm links that already overlap with the arm
stretched straight up (q = 0): the crude link cylinders overlap at the elbow, as MoveIt's setup
assistant disables "default" collisions; and shapes on neighbouring links that stay apart over
the whole range of the joint between them (a tool and link5: its "never" collisions). Fixed
shapes never meet each other (nothing moves them).

A model is immutable and shared: every thread checks with its own pinocchio data. Frames:
everything in the arm's base_link frame; `base` (4, 4) places base_link in the world.
"""
from __future__ import annotations

import math
import threading
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from functools import lru_cache

import numpy as np
import pinocchio as pin

from landscape.robot.arm import JOINT_AXES, ArmModel
from landscape.robot.kinematics import Kinematics

from .distance_bounds import PairTable, build_bounds, pair_levers
from .docking import Dock
from .shapes import ARM_LINKS, Geometry, arm_description

DEFAULT_MARGIN = 0.005   # m: closer than this is a contact
_ACTIVE_CACHE = 64       # distinct (exclude, allow) requests remembered per model


class CollisionModelError(ValueError):
    """A request naming a body the cell does not have, or a scene change that cannot be."""


@dataclass(frozen=True)
class AllowedContact:
    """Bodies a and b may touch, and why (e.g. "coupling gripper", "grasp block_1")."""

    reason: str
    a: str
    b: str

    @property
    def key(self) -> frozenset[str]:
        return frozenset((self.a, self.b))


class CollisionModel:
    """The shapes of the cell at one moment, ready to check.

    geometries: arm links first (ARM_LINKS), then the rest; pairs (P, 2) geometry indices, the
    moving shape first; pair_bodies: their bodies. known: every body name the cell has (also
    those absent now: a removed part, a tool on the flange), for checking requests. docks:
    contacts allowed in a docking corridor only (docking.py); `docks` maps their pairs to
    their Dock.
    """

    def __init__(self, arm: ArmModel, base: np.ndarray, geometries: Sequence[Geometry],
                 known: Iterable[str], allowed: Iterable[AllowedContact] = (),
                 margin: float = DEFAULT_MARGIN, docks: Iterable[Dock] = ()):
        if not margin > 0:
            raise CollisionModelError(f"the margin must be positive, got {margin!r} m")
        self.arm, self.margin = arm, float(margin)
        self.base = np.asarray(base, dtype=float)
        self.kinematics = Kinematics(arm)
        self.geometries = tuple(geometries)
        self.known = frozenset(known)
        self.allowed = tuple(allowed)
        self._check_names(b for c in self.allowed for b in (c.a, c.b))
        self.pin_model, _ = arm_description(arm)

        moving = [i for i, g in enumerate(self.geometries) if g.link > 0]
        fixed = [i for i, g in enumerate(self.geometries) if g.link == 0]
        slot = {g: k for k, g in enumerate(moving)} | {g: k for k, g in enumerate(fixed)}
        axes = np.eye(3)[["xyz".index(a) for a in JOINT_AXES]]
        self.bounds = build_bounds([self.geometries[i] for i in moving],
                                   [self.geometries[i] for i in fixed],
                                   np.array(arm.joint_origins), axes)
        self.geom_model = pin.GeometryModel()
        for g in self.geometries:
            self.geom_model.addGeometryObject(
                pin.GeometryObject(g.name, g.link, pin.SE3(g.placement), g.shape))
        skip = _touching_arm_links(arm, self.margin)
        pairs = []
        for i in moving:
            for j in range(len(self.geometries)):
                gi, gj = self.geometries[i], self.geometries[j]
                if (j == i or (gj.link > 0 and j < i) or gi.body == gj.body
                        or gi.link == gj.link or frozenset((gi.body, gj.body)) in skip):
                    continue
                pairs.append((i, j))
        apart = self._apart_over_one_joint(pairs, slot)
        pairs = [p for p in pairs if p not in apart]
        for i, j in pairs:
            self.geom_model.addCollisionPair(pin.CollisionPair(int(i), int(j)))
        self.pairs = np.array(pairs, dtype=int).reshape(-1, 2)
        self.pair_bodies = tuple((self.geometries[i].body, self.geometries[j].body)
                                 for i, j in pairs)
        self.pair_shapes = tuple((self.geometries[i].name, self.geometries[j].name)
                                 for i, j in pairs)
        a = np.array([slot[i] for i, _ in pairs], dtype=int)
        b = np.array([slot[j] for _, j in pairs], dtype=int)
        fixed_b = np.array([self.geometries[j].link == 0 for _, j in pairs], dtype=bool)
        self.pair_table = PairTable(a, b, fixed_b, pair_levers(self.bounds, a, b, fixed_b))
        # Pairs allowed in a docking corridor only (the bare flange and an unmounted tool, a
        # mounted tool and its rack).
        corridors = {(d.a, d.b): d for d in docks}
        self.docks = {k: corridors[bodies] for k, bodies in enumerate(self.pair_bodies)
                      if bodies in corridors}
        self._local = threading.local()
        self._active: dict = {}    # (exclude, allow) -> active pairs, for repeated requests

    def _apart_over_one_joint(self, pairs: list[tuple[int, int]],
                              slot: dict[int, int]) -> set[tuple[int, int]]:
        """Pairs of moving shapes on neighbouring links (a tool or held part and link5) that stay
        at least the margin apart over the whole range of the one joint between them ("never in
        collision"). The joint is sampled every `margin / r` rad (r: the far shape's distance
        to the joint's axis), so between samples nothing moves more than margin / 2."""
        candidates = [(i, j) for i, j in pairs if self.geometries[j].link > 0
                      and abs(self.geometries[i].link - self.geometries[j].link) == 1]
        if not candidates:
            return set()
        gm = self.geom_model
        for i, j in candidates:
            gm.addCollisionPair(pin.CollisionPair(int(i), int(j)))
        data, gdata = self.pin_model.createData(), pin.GeometryData(gm)
        apart = set()
        for k, (i, j) in enumerate(candidates):
            far = max(i, j, key=lambda g: self.geometries[g].link)
            joint = self.geometries[far].link - 1
            r = self.bounds.lever[slot[far], joint]
            lo, hi = self.arm.joint_min[joint], self.arm.joint_max[joint]
            q = np.zeros(self.pin_model.nq)
            nearest = math.inf
            for angle in np.linspace(lo, hi, max(2, math.ceil((hi - lo) * r / self.margin) + 1)):
                q[joint] = angle
                pin.updateGeometryPlacements(self.pin_model, data, gm, gdata, q)
                nearest = min(nearest, pin.computeDistance(gm, gdata, k).min_distance)
            if nearest >= 1.5 * self.margin:
                apart.add((i, j))
        gm.removeAllCollisionPairs()
        return apart

    # ---- what a check looks at ----------------------------------------------------------------

    def active_pairs(self, exclude: Iterable[str] = (),
                     allow: Iterable[AllowedContact] = ()) -> np.ndarray:
        """Indices of the pairs to check: all but those with an excluded body and those the
        model's and the given allowed contacts name. Unknown body names raise
        CollisionModelError (a typo must not silently check nothing)."""
        key = (frozenset(exclude), frozenset(allow))
        found = self._active.get(key)
        if found is None:
            exclude, allow = key
            self._check_names(exclude | {b for c in allow for b in (c.a, c.b)})
            allowed = {c.key for c in self.allowed + tuple(allow)}
            found = np.array([k for k, (a, b) in enumerate(self.pair_bodies)
                              if a not in exclude and b not in exclude
                              and frozenset((a, b)) not in allowed], dtype=int)
            if len(self._active) < _ACTIVE_CACHE:
                self._active[key] = found
        return found

    def data(self) -> tuple[pin.Data, pin.GeometryData]:
        """This thread's pinocchio data for the model (checks write only their data, so any
        number of threads check one model at once)."""
        local = self._local
        if not hasattr(local, "data"):
            local.data = (self.pin_model.createData(), pin.GeometryData(self.geom_model))
        return local.data

    def to_world(self, points: np.ndarray) -> np.ndarray:
        """Points (..., 3) from base_link to the world."""
        return points @ self.base[:3, :3].T + self.base[:3, 3]

    def bodies(self) -> tuple[str, ...]:
        """The bodies present, arm links first."""
        return tuple(dict.fromkeys(g.body for g in self.geometries))

    def _check_names(self, names: Iterable[str]) -> None:
        unknown = sorted(set(names) - self.known)
        if unknown:
            raise CollisionModelError(f"unknown bod{'ies' if len(unknown) > 1 else 'y'} "
                                      f"{', '.join(unknown)}; the cell has "
                                      f"{', '.join(sorted(self.known))}")


@lru_cache(maxsize=8)
def _touching_arm_links(arm: ArmModel, margin: float) -> frozenset[frozenset[str]]:
    """Pairs of arm links never checked: adjacent ones, and those within `margin` of each other
    at q = 0 (overlapping housings, not collisions)."""
    model, links = arm_description(arm)
    skip = {frozenset((ARM_LINKS[i], ARM_LINKS[i + 1])) for i in range(len(ARM_LINKS) - 1)}
    geoms = pin.GeometryModel()
    for g in links:
        geoms.addGeometryObject(pin.GeometryObject(g.name, g.link, pin.SE3(g.placement), g.shape))
    candidates = [(i, j) for i in range(len(links)) for j in range(i + 2, len(links))]
    for i, j in candidates:
        geoms.addCollisionPair(pin.CollisionPair(i, j))
    data, gdata = model.createData(), pin.GeometryData(geoms)
    pin.computeDistances(model, data, geoms, gdata, np.zeros(model.nq))
    for k, (i, j) in enumerate(candidates):
        if gdata.distanceResults[k].min_distance < margin:
            skip.add(frozenset((ARM_LINKS[i], ARM_LINKS[j])))
    return frozenset(skip)
