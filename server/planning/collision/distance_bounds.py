"""The broad phase: cheap lower bounds on distances, for whole stretches of a motion at once.

Every moving shape (on link1..link6, the mounted tool and a held part included) has a bounding
sphere fixed in its link; every fixed shape (base_link, fixtures, parts, tools in the rack)
has a bounding box, and the floor is a box 1 km deep. A lower bound on the distance of a pair
is then sphere-to-box (or sphere-to-sphere between two moving shapes), in numpy, for thousands
of (pair, configuration) at once.

Motion bound: when the joints step by dq (6,) along a straight line in joint space, no point of
a shape on link l moves more than sum_j lever[j] |dq_j| (m): joint j turns every point beyond
it on a circle about its axis, of radius at most the point's distance to the joint's origin,
which the chain bounds by |origin of joint j+1| + ... + |origin of joint l| + |sphere centre|
+ sphere radius (triangle inequality; no configuration makes it larger); for joint l itself,
whose axis is fixed in the link, the distance to the axis, and none for a shape round about
that axis (a cylinder on it: turning leaves the space it fills unchanged). Over samples the
bound adds up: (travel of each joint, `joint_travel`) @ levers. Two moving shapes move relative
to each other only by the joints between their links (`pair_levers`), and not by the joint
next to the nearer one if that one is round about its axis (link5 about J6).

`uncertain_stretches` splits a sampled motion in halves, recursively, per pair: a stretch of
samples is clear when the bound at its middle sample, less what the pair can move within the
stretch, is at least the margin. What remains are stretches that need exact distances
(check.py). Shapes: N samples, G moving shapes, S fixed shapes, P pairs.
"""
from __future__ import annotations

from dataclasses import dataclass

import coal
import numpy as np
import pinocchio as pin

from .shapes import Geometry

_FLOOR_DEPTH = 1000.0   # m: the half-space is bounded by a box this deep and this wide
_ON_AXIS = 1e-9         # m (and sine): a shape this close to a joint's axis is on it


@dataclass(frozen=True, eq=False)
class Bounds:
    """Bounding volumes of a scene's shapes.

    Moving shapes (G): link (G,) int 1..6; centre (G, 3) m, sphere centres in their link's
    frame; radius (G,) m; lever (G, 6) m/rad, the motion bound per joint step; round_next (G,)
    bool: the shape is a solid of revolution about the next joint's axis (link5's cylinder
    about J6), so that joint's turning never changes a distance to it.
    Fixed shapes (S): box_centre (S, 3) m and box_axes (S, 3, 3) (columns: the box's axes)
    in the base_link frame, box_half (S, 3) m half extents; box_round_next (S,) bool: round
    about J1's axis (the base column).
    """

    link: np.ndarray
    centre: np.ndarray
    radius: np.ndarray
    lever: np.ndarray
    round_next: np.ndarray
    box_centre: np.ndarray
    box_axes: np.ndarray
    box_half: np.ndarray
    box_round_next: np.ndarray

    def __post_init__(self):
        # The centres in homogeneous coordinates (G, 4), for sphere_centres.
        object.__setattr__(self, "centre_h", np.concatenate(
            [self.centre, np.ones((len(self.centre), 1))], axis=1))


def build_bounds(moving: list[Geometry], fixed: list[Geometry], joint_origins: np.ndarray,
                 joint_axes: np.ndarray) -> Bounds:
    """Bounds of the moving shapes (link >= 1) and the fixed ones (link 0); joint_origins
    (6, 3) m: each joint's origin in its parent link (ArmModel.joint_origins); joint_axes
    (6, 3): each joint's unit axis, the same in its own link and its parent at q = 0."""
    origins = np.asarray(joint_origins, dtype=float)
    reach = np.linalg.norm(origins, axis=1)                                  # (6,)
    G = len(moving)
    link = np.array([g.link for g in moving], dtype=int)
    centre, radius, lever = np.zeros((G, 3)), np.zeros(G), np.zeros((G, 6))
    round_next = np.zeros(G, dtype=bool)
    for i, g in enumerate(moving):
        local_centre, half = _local_box(g.shape)
        c = centre[i] = g.placement[:3, :3] @ local_centre + g.placement[:3, 3]
        radius[i] = float(np.linalg.norm(half))
        for j in range(g.link - 1):   # joints before the shape's own: by distance to origin
            lever[i, j] = reach[j + 1:g.link].sum() + np.linalg.norm(c) + radius[i]
        # The shape's own joint has its axis fixed in the shape's link: distance to the axis,
        # or nothing at all for a shape round about that axis (its turning moves no surface).
        axis = joint_axes[g.link - 1]
        own = np.linalg.norm(c - (c @ axis) * axis) + radius[i]
        lever[i, g.link - 1] = 0.0 if _round_about(g, np.zeros(3), axis) else own
        if g.link < 6:
            round_next[i] = _round_about(g, origins[g.link], joint_axes[g.link])
    S = len(fixed)
    box_centre, box_axes, box_half = np.zeros((S, 3)), np.zeros((S, 3, 3)), np.zeros((S, 3))
    box_round_next = np.zeros(S, dtype=bool)
    for i, g in enumerate(fixed):
        local_centre, local_axes, half = _fixed_box(g.shape)
        box_axes[i] = g.placement[:3, :3] @ local_axes
        box_centre[i] = g.placement[:3, :3] @ local_centre + g.placement[:3, 3]
        box_half[i] = half
        box_round_next[i] = _round_about(g, origins[0], joint_axes[0])
    return Bounds(link, centre, radius, lever, round_next, box_centre, box_axes, box_half,
                  box_round_next)


def _round_about(g: Geometry, origin: np.ndarray, axis: np.ndarray) -> bool:
    """Is the shape a solid of revolution about the line through origin (3,) along axis (3,),
    both in its link's frame? (A cylinder or capsule on that line, or a sphere centred on it.)"""
    if not isinstance(g.shape, (coal.Cylinder, coal.Capsule, coal.Sphere)):
        return False
    c = g.placement[:3, 3] - origin
    on_line = np.linalg.norm(c - (c @ axis) * axis) < _ON_AXIS
    along = isinstance(g.shape, coal.Sphere) or np.linalg.norm(
        np.cross(g.placement[:3, 2], axis)) < _ON_AXIS
    return bool(on_line and along)


def pair_levers(bounds: Bounds, a: np.ndarray, b: np.ndarray, fixed: np.ndarray) -> np.ndarray:
    """(P, 6) m/rad: how far the shapes of each pair can move relative to each other per joint
    step. Against a fixed shape, the moving one's levers; between two moving shapes, those of
    the one further out along the arm, for the joints between the two links only (the rest
    moves both together). The joint next to the nearer shape counts for nothing when that
    shape is round about its axis."""
    out = bounds.lever[a].copy()
    out[fixed & bounds.box_round_next[np.where(fixed, b, 0)], 0] = 0.0
    for p in np.flatnonzero(~fixed):
        near, far = sorted((a[p], b[p]), key=lambda g: bounds.link[g])
        out[p] = bounds.lever[far]
        out[p, :bounds.link[near]] = 0.0
        if bounds.round_next[near]:
            out[p, bounds.link[near]] = 0.0
    return out


def _local_box(shape) -> tuple[np.ndarray, np.ndarray]:
    """Centre (3,) and half extents (3,) of a coal shape's box in its own frame."""
    shape.computeLocalAABB()
    lo, hi = np.asarray(shape.aabb_local.min_), np.asarray(shape.aabb_local.max_)
    return (lo + hi) / 2.0, (hi - lo) / 2.0


def _fixed_box(shape) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(centre (3,), axes (3, 3), half extents (3,)) of a fixed shape in its own frame; a
    half-space n.x <= d becomes a box below its plane."""
    if isinstance(shape, coal.Halfspace):
        n = np.asarray(shape.n, dtype=float)
        axes = pin.Quaternion.FromTwoVectors(np.array([0.0, 0.0, 1.0]), n).matrix()
        return n * (shape.d - _FLOOR_DEPTH), axes, np.full(3, _FLOOR_DEPTH)
    centre, half = _local_box(shape)
    return centre, np.eye(3), half


def sphere_centres(bounds: Bounds, frames: np.ndarray) -> np.ndarray:
    """(n, G, 3) m: the sphere centres in base_link, from link frames (n, 6, 4, 4)."""
    F = frames[:, bounds.link - 1, :3, :]                               # (n, G, 3, 4)
    return (F @ bounds.centre_h[:, :, None])[..., 0]


class SphereCentres:
    """Sphere centres of the moving shapes in base_link at samples of a motion, computed on
    first use (the broad phase visits only some samples): values (N, G, 3) m, valid where
    `ensure` has been called. kinematics: gives link frames (Kinematics.link_frames); q (N, 6)
    rad."""

    def __init__(self, bounds: Bounds, kinematics, q: np.ndarray):
        self.bounds, self.kinematics, self.q = bounds, kinematics, q
        self.values = np.empty((len(q), len(bounds.radius), 3))
        self._done = np.zeros(len(q), dtype=bool)

    def ensure(self, samples: np.ndarray) -> np.ndarray:
        """Compute the centres at these samples (K,) if not done yet; returns `values`."""
        new = np.unique(samples[~self._done[samples]])
        if len(new):
            frames = self.kinematics.link_frames(self.q[new])
            self.values[new] = sphere_centres(self.bounds, frames)
            self._done[new] = True
        return self.values


def joint_travel(q: np.ndarray) -> np.ndarray:
    """(N, 6) rad: how far each joint has turned (absolute steps added up) from sample 0 to
    sample k along q (N, 6). A pair with levers (6,) moves at most (T[e] - T[s]) @ levers
    from sample s to sample e (joints linear between samples)."""
    steps = np.abs(np.diff(q, axis=0))
    return np.concatenate([np.zeros((1, q.shape[1])), np.cumsum(steps, axis=0)])


def sphere_box(bounds: Bounds, centres: np.ndarray, moving: np.ndarray,
               box: np.ndarray) -> np.ndarray:
    """(C,) lower bounds on the distance from moving shapes (C,) with sphere centres (C, 3)
    to fixed shapes box (C,)."""
    local = np.einsum("ci,cij->cj", centres - bounds.box_centre[box], bounds.box_axes[box])
    outside = np.maximum(np.abs(local) - bounds.box_half[box], 0.0)
    return np.linalg.norm(outside, axis=1) - bounds.radius[moving]


@dataclass(frozen=True, eq=False)
class PairTable:
    """The pairs to bound: a (P,) moving shape; b (P,) the other, a fixed shape's box index
    when fixed[p], else a moving shape index; lever (P, 6) m/rad (pair_levers)."""

    a: np.ndarray
    b: np.ndarray
    fixed: np.ndarray
    lever: np.ndarray


def lower_bounds(bounds: Bounds, pairs: PairTable, centres: np.ndarray, pair: np.ndarray,
                 sample: np.ndarray) -> np.ndarray:
    """(C,) lower bounds on the distance of pairs (C,) (indices into `pairs`) at samples (C,),
    with sphere centres (N, G, 3)."""
    a, b, fixed = pairs.a[pair], pairs.b[pair], pairs.fixed[pair]
    out = np.empty(len(pair))
    if fixed.any():
        out[fixed] = sphere_box(bounds, centres[sample[fixed], a[fixed]], a[fixed], b[fixed])
    free = ~fixed
    if free.any():
        gap = centres[sample[free], a[free]] - centres[sample[free], b[free]]
        out[free] = (np.linalg.norm(gap, axis=1) - bounds.radius[a[free]]
                     - bounds.radius[b[free]])
    return out


def uncertain_stretches(bounds: Bounds, pairs: PairTable, centres: SphereCentres,
                        travel: np.ndarray, active: np.ndarray, margin: float
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The stretches of samples the broad phase cannot clear: (pair (L,), start (L,), end (L,),
    bounds computed). active (K,): the pair indices to check; travel (N, 6): joint_travel.

    A stretch [s, e] is clear for a pair when its bound at the middle sample m, less the pair's
    motion from m to the farther end, is at least `margin`. If not, it is halved, unless it is
    a single step or the bound at m alone is below the margin (halving cannot clear the halves
    next to m): then it goes to the narrow phase whole."""
    last = len(travel) - 1
    pair = np.asarray(active, dtype=int)
    start = np.zeros(len(pair), dtype=int)
    end = np.full(len(pair), last, dtype=int)
    computed = 0
    nothing = np.zeros(0, dtype=int)
    kept: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = [(nothing, nothing, nothing)]
    while len(pair):
        mid = (start + end) // 2
        lever = pairs.lever[pair]
        reach = np.maximum(np.einsum("kj,kj->k", travel[mid] - travel[start], lever),
                           np.einsum("kj,kj->k", travel[end] - travel[mid], lever))
        bound = lower_bounds(bounds, pairs, centres.ensure(mid), pair, mid)
        computed += len(pair)
        unclear = bound - reach < margin
        whole = unclear & ((end - start <= 1) | (bound < margin))
        kept.append((pair[whole], start[whole], end[whole]))
        split = unclear & ~whole
        pair, start, end, mid = pair[split], start[split], end[split], mid[split]
        pair = np.concatenate([pair, pair])
        start, end = np.concatenate([start, mid]), np.concatenate([mid, end])
    pair, start, end = (np.concatenate(x) for x in zip(*kept))
    return pair, start, end, computed
