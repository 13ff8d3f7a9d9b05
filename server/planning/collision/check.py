"""Checking motions and configurations against a CollisionModel.

`check_motion` takes joint positions sampled every dt (the executor plays them one per cycle,
moving linearly in joint space in between) and finds the first place where a pair that may not
touch comes closer than the margin. The guarantee, for every active pair: the distance is at
least the margin at every configuration checked, and between two checks no point of either
shape moves more than the margin (the motion bound of bounds.py) or, where the pair is far
apart, more than its distance less the margin. So nothing passes between checks: a motion that
is clear never makes two shapes overlap, anywhere along it, and one that comes within the margin
at a check is refused there.

How: the broad phase (bounds.py) clears most (pair, stretch of samples) at once with sphere and
box bounds; what it leaves are runs of samples per pair, walked by conservative advancement: at
each check the exact distance d (coal, through pinocchio) puts the next check max(d - margin,
margin) further along the pair's motion bound. All runs advance together, the one furthest
behind first, so the first contact found is the earliest and ends the walk.

Allowed contacts (model.AllowedContact) and excluded bodies drop pairs from a check; the pairs
of a docking corridor (the bare flange and an unmounted tool, a mounted tool and its rack:
docking.py) are checked only where the flange is out of the corridor. A pair that
starts within the margin (the arm resting on what it touched, a part lifted off the table) may
leave it: until it first reaches the margin it is held only to its starting distance less
LEAVE_TOLERANCE, checked at least every LEAVE_TOLERANCE of motion.

Units: joints rad, distances m, times s; points are in the world frame.
"""
from __future__ import annotations

import bisect
import heapq
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np
import pinocchio as pin

from .distance_bounds import (SphereCentres, joint_travel, lower_bounds, sphere_centres,
                     uncertain_stretches)
from .docking import strict_stretches
from .model import AllowedContact, CollisionModel

LEAVE_TOLERANCE = 0.001   # m: how much closer a pair starting within the margin may come
_GJK_SLACK = 1e-6         # m: two coal calls on one pair may differ by GJK's tolerance

Marks = Sequence[tuple[int, Any]] | Mapping[int, Any]


@dataclass(frozen=True, eq=False)
class Contact:
    """Where a motion first comes within the margin of something it may not touch.

    bodies: (moving body, other body), e.g. ("link3", "table"); shapes: the two shapes (a tool
    or a body of several shapes names the shape, "gripper/finger_left"); distance (m) at that
    configuration (below the margin; negative: overlapping by that much); time (s) after the
    start, sample: the sample at or before it, fraction: time / duration (0 for a single
    configuration); segment: the label of the first mark at or after it (with marks at the
    samples where waypoints are reached, the waypoint the arm was heading to), None without
    marks; q (6,) rad: the configuration; point (3,) m: midway between the nearest points.
    """

    bodies: tuple[str, str]
    shapes: tuple[str, str]
    distance: float
    time: float
    sample: int
    fraction: float
    segment: Any
    q: np.ndarray
    point: np.ndarray

    def metadata(self) -> dict[str, str]:
        """The contact as strings, for an ErrorInfo's metadata."""
        out = {"body_a": self.bodies[0], "body_b": self.bodies[1],
               "shape_a": self.shapes[0], "shape_b": self.shapes[1],
               "time": f"{self.time:.3f}", "sample": str(self.sample),
               "fraction": f"{self.fraction:.4f}", "distance": f"{self.distance:.4f}"}
        if self.segment is not None:
            out["segment"] = str(self.segment)
        return out

    def within(self, first: int, samples: int, dt: float) -> "Contact":
        """The contact of a piece of a longer motion (played one sample per dt), in terms of
        the whole: the piece starts at the whole's sample `first`, which has `samples`."""
        time = self.time + first * dt
        return replace(self, time=time, sample=self.sample + first,
                       fraction=time / ((samples - 1) * dt) if samples > 1 else 0.0)

    def __str__(self) -> str:
        where = f" (segment {self.segment})" if self.segment is not None else ""
        return (f"{self.bodies[0]} meets {self.bodies[1]} at t = {self.time:.3f} s, "
                f"{100 * self.fraction:.1f} % of the motion{where}: "
                f"{1000 * self.distance:.1f} mm apart")


@dataclass(frozen=True, eq=False)
class CheckResult:
    """contact: the first contact, None if the motion is clear. configurations: how many
    configurations the narrow phase placed; pair_checks: exact distances computed (coal);
    bound_checks: broad-phase bounds computed (a sphere against a box or a sphere, for a
    stretch of samples). started_within: pairs that began within the margin and were let
    leave (bodies)."""

    contact: Contact | None
    configurations: int
    pair_checks: int
    bound_checks: int
    started_within: tuple[tuple[str, str], ...] = field(default=())

    @property
    def clear(self) -> bool:
        return self.contact is None


@dataclass(frozen=True, eq=False)
class Clearance:
    """The smallest distance (m) of the active pairs at one configuration, with its bodies,
    shapes and nearest points (2, 3) in the world; distance = inf (and bodies None) when no
    pair comes closer than the limit asked for."""

    distance: float
    bodies: tuple[str, str] | None = None
    shapes: tuple[str, str] | None = None
    points: np.ndarray | None = None


def check_motion(model: CollisionModel, positions, dt: float, marks: Marks = (), *,
                 exclude: Iterable[str] = (), allow: Iterable[AllowedContact] = (),
                 allow_leaving: bool = True) -> CheckResult:
    """Check the motion through joint positions (N, 6) rad sampled every dt s, against the
    model's margin.

    marks: (sample, label) pairs or {sample: label}, e.g. Trajectory.marks; exclude: bodies
    left out (the surface a guarded move is meant to touch); allow: contacts allowed for this
    check besides the model's own. allow_leaving: pairs within the margin at the first sample
    may move apart (module docstring); False: they are a contact at time 0. Raises ValueError
    on malformed input, CollisionModelError on unknown body names."""
    Q = _positions(positions)
    if not (math.isfinite(dt) and dt > 0):
        raise ValueError(f"dt must be positive, got {dt!r}")
    margin = model.margin
    active = model.active_pairs(exclude, allow)
    bounds, table = model.bounds, model.pair_table
    travel = joint_travel(Q)
    centres = SphereCentres(bounds, model.kinematics, Q)
    stretches = uncertain_stretches(bounds, table, centres, travel, active, margin)
    bound_checks = stretches[-1]
    runs = []
    for p, s, e in _runs(*stretches[:-1]):
        dock = model.docks.get(p)
        parts = [(s, e)] if dock is None else strict_stretches(
            dock.inside(model.kinematics.forward(Q[s:e + 1])), s)
        for s, e in parts:
            along = (travel[s:e + 1] @ table.lever[p]).tolist()
            runs.append(_Run(p, s, e, along, float(s), along[0], margin, margin))
    walk = _Walk(model, Q, margin, allow_leaving)
    walk.walk(runs)
    contact = None
    if walk.first is not None:
        contact = _contact(model, walk.first, Q, dt, _sorted_marks(marks))
    return CheckResult(contact, walk.configurations, walk.pair_checks, bound_checks,
                       tuple(model.pair_bodies[p] for p in walk.leaving))


def clearance(model: CollisionModel, q, *, exclude: Iterable[str] = (),
              allow: Iterable[AllowedContact] = (), limit: float = math.inf) -> Clearance:
    """The smallest distance between active pairs at joints q (6,) rad, exact up to `limit`
    (m): pairs whose broad-phase bound is at least `limit` are not computed (a jog only needs
    to know how near it is within its slow-down range)."""
    Q = _positions(np.asarray(q, dtype=float).reshape(1, -1))
    active = model.active_pairs(exclude, allow)
    data, gdata = model.data()
    pin.updateGeometryPlacements(model.pin_model, data, model.geom_model, gdata, Q[0])
    frames = np.array([[data.oMi[i].homogeneous for i in range(1, 7)]])     # (1, 6, 4, 4)
    bound = lower_bounds(model.bounds, model.pair_table, sphere_centres(model.bounds, frames),
                         active, np.zeros(len(active), dtype=int))
    if not len(active) or bound.min() >= limit:
        return Clearance(math.inf)
    # The pair nearest by its bound gives a distance d; only pairs whose bound is below d can
    # be nearer (below 0 for an overlap: bounds hold for separations, not for depths).
    # pinocchio then computes those (its active pairs) in one pass, in C++.
    nearest = int(active[int(np.argmin(bound))])
    cutoff = pin.computeDistance(model.geom_model, gdata, nearest).min_distance
    near = active[bound < min(limit, max(cutoff, 0.0) + _GJK_SLACK)]
    gdata.deactivateAllCollisionPairs()
    for k in near:
        gdata.activateCollisionPair(int(k))
    pin.computeDistances(model.geom_model, gdata)
    distances = [gdata.distanceResults[int(k)].min_distance for k in near]
    best = int(near[int(np.argmin(distances))])
    result = gdata.distanceResults[best]
    if result.min_distance >= limit:
        return Clearance(math.inf)
    points = model.to_world(np.array([result.getNearestPoint1(), result.getNearestPoint2()]))
    return Clearance(float(result.min_distance), model.pair_bodies[best],
                     model.pair_shapes[best], points)


# ---- the narrow phase -------------------------------------------------------------------------

@dataclass
class _Hit:
    pair: int
    u: float            # samples (fractional) from the start
    distance: float
    q: np.ndarray
    points: np.ndarray  # (2, 3) base_link


@dataclass
class _Run:
    """One pair's walk from sample s to sample e: at u (fractional sample), having moved `at`
    (m) by its bound; along: the cumulative bound at samples s..e (floats, m). A check below
    `threshold` is a contact; the next check comes max(d - threshold, floor) further on."""

    pair: int
    s: int
    e: int
    along: list[float]
    u: float
    at: float
    threshold: float
    floor: float


class _Walk:
    """Conservative advancement along runs of sample steps, all pairs together, earliest
    first: it stops at the first contact, as soon as every run has reached it."""

    def __init__(self, model: CollisionModel, Q: np.ndarray, margin: float,
                 allow_leaving: bool):
        self.model, self.Q, self.margin = model, Q, margin
        self.allow_leaving = allow_leaving
        self.data, self.gdata = model.data()
        self.placed_u: float | None = None
        self.configurations = self.pair_checks = 0
        self.first: _Hit | None = None
        self.leaving: list[int] = []

    def walk(self, runs: list[_Run]) -> None:
        heap = [(r.u, k) for k, r in enumerate(runs)]
        heapq.heapify(heap)
        while heap:
            u, k = heapq.heappop(heap)
            if self.first is not None and u >= self.first.u:
                return                     # every other run is there or further on too
            if self.step(runs[k]):
                heapq.heappush(heap, (runs[k].u, k))

    def distance(self, pair: int, u: float):
        if u != self.placed_u:
            i = min(int(u), len(self.Q) - 1)
            f = u - i
            q = self.Q[i] if f == 0.0 else self.Q[i] + f * (self.Q[i + 1] - self.Q[i])
            pin.updateGeometryPlacements(self.model.pin_model, self.data, self.model.geom_model,
                                         self.gdata, q)
            self.placed_u, self.q = u, q
            self.configurations += 1
        self.pair_checks += 1
        return pin.computeDistance(self.model.geom_model, self.gdata, pair)

    def step(self, run: _Run) -> bool:
        """Check the run where it is and move it on; False when it is done. The last sample of
        the motion is always checked."""
        result = self.distance(run.pair, run.u)
        d = result.min_distance
        if run.u == 0.0 and d < self.margin and self.allow_leaving:
            run.threshold, run.floor = d - LEAVE_TOLERANCE, LEAVE_TOLERANCE
            self.leaving.append(run.pair)
        elif d >= self.margin:
            run.threshold, run.floor = self.margin, self.margin
        if d < run.threshold:
            self.first = _Hit(run.pair, run.u, d, self.q.copy(),
                              np.array([result.getNearestPoint1(), result.getNearestPoint2()]))
            return False
        if run.u >= run.e:
            return False
        along = run.along
        run.at += max(d - run.threshold, run.floor)
        if run.at < along[-1]:      # where the bound reaches `at`: between samples i and i + 1
            i = bisect.bisect_right(along, run.at) - 1
            run.u = run.s + i + (run.at - along[i]) / (along[i + 1] - along[i])
            return True
        if run.e == len(self.Q) - 1:
            run.u = float(run.e)
            return True
        return False


def _runs(pair: np.ndarray, start: np.ndarray, end: np.ndarray) -> list[tuple[int, int, int]]:
    """(pair, first sample, last sample) of the stretches of each pair merged where they meet
    or overlap, in the order of their first sample."""
    if not len(pair):
        return []
    order = np.lexsort((start, pair))
    c, s, e = pair[order].tolist(), start[order].tolist(), end[order].tolist()
    runs = [[c[0], s[0], e[0]]]
    for ci, si, ei in zip(c[1:], s[1:], e[1:]):
        run = runs[-1]
        if ci == run[0] and si <= run[2]:
            run[2] = max(run[2], ei)
        else:
            runs.append([ci, si, ei])
    return sorted((tuple(r) for r in runs), key=lambda r: r[1])


# ---- input and output -------------------------------------------------------------------------

def _positions(positions) -> np.ndarray:
    Q = np.asarray(positions, dtype=float)
    if Q.ndim != 2 or Q.shape[1] != 6 or len(Q) < 1:
        raise ValueError(f"positions must have shape (N >= 1, 6), got {Q.shape}")
    if not np.all(np.isfinite(Q)):
        raise ValueError("positions must be finite")
    return Q


def _sorted_marks(marks: Marks) -> list[tuple[int, Any]]:
    items = marks.items() if isinstance(marks, Mapping) else marks
    return sorted(((int(k), label) for k, label in items), key=lambda m: m[0])


def _contact(model: CollisionModel, hit: _Hit, Q: np.ndarray, dt: float,
             marks: list[tuple[int, Any]]) -> Contact:
    last = len(Q) - 1
    segment = next((label for k, label in marks if k >= hit.u - 1e-9), None)
    points = model.to_world(hit.points)
    return Contact(model.pair_bodies[hit.pair], model.pair_shapes[hit.pair], float(hit.distance),
                   hit.u * dt, min(int(hit.u), last), hit.u / last if last else 0.0, segment,
                   hit.q, points.mean(axis=0))
