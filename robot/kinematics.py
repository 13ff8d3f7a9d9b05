"""Kinematics of the TX90-class arm: forward, closed-form inverse, and the LLI configurations.

The arm is an ortho-parallel 6R arm with a spherical wrist (Brandstoetter, Angerer, Hofbaur
2014): J1 vertical; J2 and J3 parallel and perpendicular to J1; J4, J5, J6 meet in one point,
the wrist centre. Everything is derived from `ArmModel.joint_origins` and `JOINT_AXES`
(sim/arm.py), so the TX90, TX90L and TX90XL share this code.

Units and shapes: poses are (4, 4) homogeneous matrices of the flange (URDF frame tool0) in the
base_link frame, metres; joint vectors are (6,) in radians, joint 1 first.

Configurations (LLI_Config), as this module labels a joint vector q:

- shoulder: RIGHTY when the wrist centre lies in front of the J1 axis, i.e. at x >= 0 in the
  frame of link 1 (the arm reaches forward, the side J2 is offset to); LEFTY when it lies
  behind (x < 0: the arm reaches backwards, J1 being turned about half a turn from RIGHTY).
- elbow: POSITIVE when q3 >= 0. Geometrically (q3 turns the forearm about +y, towards link 1's
  +x): reaching forward (wrist centre ahead of J2) POSITIVE is the elbow-up posture; reaching
  backwards it is elbow-down. With a non-zero upper-arm or forearm offset the sign is that of
  the bend between the two (q3 plus the difference of their offset angles), which is q3 for
  the TX90 family (a2 = 0).
- wrist: POSITIVE when q5 >= 0.

Angles are compared after wrapping to (-pi, pi]. On a boundary (q3 = 0, q5 = 0, wrist centre
on the shoulder-singular cylinder of radius b about J1) both labels name the same joints:
`configuration` reports RIGHTY/POSITIVE there, while `solutions` returns one solution per
branch, each tagged with its branch, so a request for either label is met.

Singular cases never give NaN: at q5 = 0 (sin q5 below `SINGULAR_EPS`) q4 is taken from q_near
and q6 absorbs the rest; with the wrist centre on the J1 axis (possible only if the lateral
offset is zero) q1 comes from q_near; a stretched arm (q3 = 0) gives two equal elbow branches.

Invalid input: `reverse` returns INVALID_ORIENTATION for a pose whose rotation is not proper
(orthonormal within `ORTHONORMAL_TOL`, determinant +1), whose last row is not (0, 0, 0, 1), or
which holds NaN/inf; `solutions` raises ValueError for such a pose. Arrays of the wrong shape,
or non-finite q_near or joint ranges, raise ValueError.

The names of configurations and reversing results are the LLI's (configurations.py); the
closed form for many poses at once, in numpy, is kinematics_batch.py; the same arm in
pinocchio, for cross-checks, Jacobians and dynamics, is pinocchio_model.py.
"""
from __future__ import annotations

import math

import numpy as np

from landscape.robot.arm import JOINT_AXES, ArmModel
from landscape.robot.closed_form import (ORTHONORMAL_TOL, REACH_TOL, SINGULAR_EPS, ClosedForm,
                                         by_bound, fit_range, is_rigid, pose_rows, vector6)
from landscape.robot.configurations import BRANCHES, Config, PosNeg, ReversingResult, Shoulder

__all__ = ["Shoulder", "PosNeg", "Config", "ReversingResult", "BRANCHES", "Kinematics",
           "wrap_angle", "ORTHONORMAL_TOL", "SINGULAR_EPS"]

_TWO_PI = 2.0 * math.pi


def _allowed(request: Config) -> frozenset[int]:
    """Indices of the branches a request (without SAME) accepts; FREE accepts both."""
    return frozenset(i for i, b in enumerate(BRANCHES)
                     if request.shoulder in (Shoulder.FREE, b.shoulder)
                     and request.elbow in (PosNeg.FREE, b.elbow)
                     and request.wrist in (PosNeg.FREE, b.wrist))


_ANY = Config()                       # reverse()'s default request: any configuration
_OF_SHOULDER = (frozenset(range(4)), frozenset(range(4, 8)))   # branches of RIGHTY, LEFTY
_ALL_BRANCHES = frozenset(range(8))

# The branches each request accepts, by the values of its fields (1..3; SAME, 0, is resolved
# first): index 16 shoulder + 4 elbow + wrist. A list, not a dict of Configs: hashing a Config
# costs more than the rest of choosing a branch.
_ALLOWED: list[frozenset[int] | None] = [None] * 64
for _s in (Shoulder.LEFTY, Shoulder.RIGHTY, Shoulder.FREE):
    for _e in (PosNeg.POSITIVE, PosNeg.NEGATIVE, PosNeg.FREE):
        for _w in (PosNeg.POSITIVE, PosNeg.NEGATIVE, PosNeg.FREE):
            _ALLOWED[16 * _s + 4 * _e + _w] = _allowed(Config(_s, _e, _w))


def wrap_angle(a):
    """Angles (any shape, rad) wrapped to (-pi, pi]."""
    a = np.asarray(a, dtype=float)
    w = a - _TWO_PI * np.round(a / _TWO_PI)
    return np.where(w <= -math.pi, w + _TWO_PI, w)


def _wrap(a: float) -> float:
    """wrap_angle of one plain float (math.remainder: numpy costs ~1 us a scalar call)."""
    w = math.remainder(a, _TWO_PI)
    return w + _TWO_PI if w <= -math.pi else w


class Kinematics:
    """Forward and closed-form inverse kinematics of one arm.

    The closed form, in the frame of link 1 (J1 turned by q1): the wrist centre C lies at
    C = flange - c4 * z_flange. Its height and distance from the J1 axis give two q1 (wrist
    centre in front of or behind the axis, the lateral offset b fixing the plane of J2/J3).
    In that plane the upper arm and forearm form a triangle with the J2-C distance: two q3 (the
    elbow bent either way) and for each one q2. The wrist then has to make
    R3_6 = (Rz(q1) Ry(q2 + q3))^T R = Rz(q4) Ry(q5) Rz(q6), a ZYZ decomposition with two
    solutions (q5 positive or negative).
    """

    def __init__(self, arm: ArmModel):
        form = self.closed_form = ClosedForm.of(arm)
        self.arm = arm
        self._base, self._base_xyz = form.base, tuple(form.base.tolist())
        self._shoulder_x, self._shoulder_z, self._lateral = (form.shoulder_x, form.shoulder_z,
                                                             form.lateral)
        self._lu, self._au = form.upper, form.upper_angle
        self._lf, self._af = form.fore, form.fore_angle
        self._flange = form.flange
        o = np.array(arm.joint_origins, dtype=float)
        # Per joint, the constant part of its transform (origin, 1 on the axis) and the indices
        # of the 2x2 rotation block about that axis, for `forward`.
        self._fixed = np.zeros((6, 4, 4))
        self._fixed[:, :3, 3] = o
        self._fixed[:, 3, 3] = 1.0
        axis = np.array(["xyz".index(a) for a in JOINT_AXES])
        self._fixed[np.arange(6), axis, axis] = 1.0
        # Rotation by t about axis i: [j, j] = [k, k] = cos t, [j, k] = -sin t, [k, j] = sin t.
        self._rot_index = (np.arange(6), (axis + 1) % 3, (axis + 2) % 3)
        self._lower = [float(v) for v in arm.joint_min]
        self._upper = [float(v) for v in arm.joint_max]

    # ---- forward ------------------------------------------------------------------------------

    def forward(self, q) -> np.ndarray:
        """Flange pose in base_link: q (6,) -> (4, 4), or batched (..., 6) -> (..., 4, 4).

        The chain base_link -> link1 -> ... -> link6 (= tool0): for each joint, a translation
        to its origin, then a rotation by q_i about its axis.
        """
        T = self._joint_transforms(q)
        out = T[..., 0, :, :]
        for i in range(1, 6):
            out = out @ T[..., i, :, :]
        return out

    def link_frames(self, q) -> np.ndarray:
        """Frames of link1 .. link6 in base_link (each at its joint, as in the URDF): q (..., 6)
        -> (..., 6, 4, 4); [..., 5, :, :] is `forward(q)`."""
        T = self._joint_transforms(q)
        out = np.empty_like(T)
        out[..., 0, :, :] = T[..., 0, :, :]
        for i in range(1, 6):
            out[..., i, :, :] = out[..., i - 1, :, :] @ T[..., i, :, :]
        return out

    def _joint_transforms(self, q) -> np.ndarray:
        """(..., 6, 4, 4): per joint, the translation to its origin, then the rotation by q_i."""
        q = np.asarray(q, dtype=float)
        if q.shape[-1:] != (6,):
            raise ValueError(f"joint vectors need a last axis of 6, got shape {q.shape}")
        c, s = np.cos(q), np.sin(q)
        T = np.broadcast_to(self._fixed, q.shape[:-1] + (6, 4, 4)).copy()
        n, j, k = self._rot_index
        T[..., n, j, j] = c
        T[..., n, k, k] = c
        T[..., n, j, k] = -s
        T[..., n, k, j] = s
        return T

    def configuration(self, q) -> Config:
        """Concrete labels (LEFTY/RIGHTY, POSITIVE/NEGATIVE) of a joint vector (6,)."""
        q = vector6(q, "q")
        # x of the wrist centre in link 1, measured from the J1 axis.
        x = (self._shoulder_x + self._lu * math.sin(q[1] + self._au)
             + self._lf * math.sin(q[1] + q[2] + self._af))
        bend = _wrap(q[2] + self._af - self._au)
        return Config(Shoulder.RIGHTY if x >= 0.0 else Shoulder.LEFTY,
                      PosNeg.POSITIVE if bend >= 0.0 else PosNeg.NEGATIVE,
                      PosNeg.POSITIVE if _wrap(q[4]) >= 0.0 else PosNeg.NEGATIVE)

    # ---- inverse, one pose (plain floats: ~10x faster than numpy on 3-vectors) -----------------

    def _shoulders(self, pose: list[list[float]], near) -> list[tuple]:
        """The first step of the closed form: per shoulder branch of a valid pose (rows),
        (q1 wrapped to (-pi, pi], si: 0 RIGHTY / 1 LEFTY, wx, cz: the wrist centre in link 1's
        x and base z); [] inside the cylinder J1 cannot reach."""
        (_, _, r02, x0), (_, _, r12, y0), (_, _, r22, z0), _ = pose
        f, lat = self._flange, self._lateral
        bx, by, bz = self._base_xyz
        cx, cy, cz = x0 - f * r02 - bx, y0 - f * r12 - by, z0 - f * r22 - bz   # wrist centre
        r2 = cx * cx + cy * cy
        x2 = r2 - lat * lat
        if x2 < -REACH_TOL:
            return []
        x = math.sqrt(max(x2, 0.0))
        rem, pi, two_pi = math.remainder, math.pi, _TWO_PI
        toward = math.atan2(cy, cx)
        out = []
        for si, wx in ((0, x), (1, -x)):
            q1 = near[0] if r2 < SINGULAR_EPS**2 else rem(toward - math.atan2(lat, wx), two_pi)
            out.append((q1 + two_pi if q1 <= -pi else q1, si, wx, cz))
        return out

    def _elbows_at(self, shoulder: tuple) -> list[tuple]:
        """The elbow branches of one shoulder (_shoulders' item), each (q3 wrapped to
        (-pi, pi], branch index of its wrist-POSITIVE solution, what _arm needs); [] if J2 is
        too far from (or too near) the wrist centre."""
        q1, si, wx, cz = shoulder
        lu, lf = self._lu, self._lf
        px, pz = wx - self._shoulder_x, cz - self._shoulder_z
        d2 = px * px + pz * pz
        cos_bend = (d2 - lu * lu - lf * lf) / (2.0 * lu * lf)
        if abs(cos_bend) > 1.0 + REACH_TOL:
            return []
        bend = math.acos(min(1.0, max(-1.0, cos_bend)))
        rem, pi, two_pi, shift = math.remainder, math.pi, _TWO_PI, self._au - self._af
        arm = (q1, px, pz, d2)
        out = []
        for ei, delta in ((0, bend), (1, -bend)):
            q3 = rem(delta + shift, two_pi)
            out.append((q3 + two_pi if q3 <= -pi else q3, 4 * si + 2 * ei, delta, arm))
        return out

    def _arm(self, pose: list[list[float]], near, elbow: tuple) -> tuple:
        """The rest of one arm solution from _elbows_at's item: (q1, q2, q3, q5 of the POSITIVE
        wrist, wrist terms for _wrist), q1, q2 wrapped to (-pi, pi]."""
        (r00, r01, r02, _), (r10, r11, r12, _), (r20, r21, r22, _), _ = pose
        q3, _, delta, (q1, px, pz, d2) = elbow
        lu, lf, au = self._lu, self._lf, self._au
        rem, pi, two_pi = math.remainder, math.pi, _TWO_PI
        if d2 < SINGULAR_EPS**2:
            phi2 = near[1] + au                         # wrist centre on J2: q2 is free
        else:
            phi2 = math.atan2(px, pz) - math.atan2(lf * math.sin(delta), lu + lf * math.cos(delta))
        q2 = rem(phi2 - au, two_pi)
        if q2 <= -pi:
            q2 += two_pi
        c1, s1 = math.cos(q1), math.sin(q1)
        # Rows a0, a1 of Rz(q1)^T R (its row 2 is R's).
        a00, a01, a02 = c1 * r00 + s1 * r10, c1 * r01 + s1 * r11, c1 * r02 + s1 * r12
        a10, a11, a12 = c1 * r10 - s1 * r00, c1 * r11 - s1 * r01, c1 * r12 - s1 * r02
        ct, st = math.cos(q2 + q3), math.sin(q2 + q3)
        # M = Ry(q2 + q3)^T Rz(q1)^T R = Rz(q4) Ry(q5) Rz(q6): rows m0, a1, m2.
        m00, m01, m02 = ct * a00 - st * r20, ct * a01 - st * r21, ct * a02 - st * r22
        sw = math.hypot(m02, a12)                       # |sin q5|
        q5 = math.atan2(sw, st * a02 + ct * r22)
        return q1, q2, q3, q5, (a10, a11, a12, m00, m01, m02, sw)

    @staticmethod
    def _wrist(terms: tuple, q5: float, negative: bool, near) -> tuple[float, float, float]:
        """(q4, q5, q6) of one wrist solution from _arms' terms and its POSITIVE q5: the
        NEGATIVE one is the same wrist turned half a turn (q4 and q6 by pi, q5 negated)."""
        a10, a11, a12, m00, m01, m02, sw = terms
        singular = sw < SINGULAR_EPS
        q4 = near[3] if singular else math.atan2(a12, m02)
        c4, s4 = math.cos(q4), math.sin(q4)
        # Row 1 of Rz(q4)^T M is (sin q6, cos q6, 0) whatever q5.
        q6 = math.atan2(c4 * a10 - s4 * m00, c4 * a11 - s4 * m01)
        if singular:
            q4 = _wrap(q4)
        if not negative:
            return q4, q5, q6
        if not singular:
            q4 = q4 + math.pi if q4 <= 0.0 else q4 - math.pi
            q6 = q6 + math.pi if q6 <= 0.0 else q6 - math.pi
        return q4, (-q5 if q5 < math.pi else q5), q6

    def _branches(self, pose: list[list[float]], near) -> list[tuple[list[float], int]]:
        """All solutions of a valid pose (rows) as (q: 6 wrapped floats, index into BRANCHES)."""
        out = []
        for elbow in (e for s in self._shoulders(pose, near) for e in self._elbows_at(s)):
            q1, q2, q3, q5, terms = self._arm(pose, near, elbow)
            for wi in (0, 1):
                out.append(([q1, q2, q3, *self._wrist(terms, q5, wi == 1, near)], elbow[1] + wi))
        return out

    def solutions(self, pose, q_near=None) -> list[tuple[np.ndarray, Config]]:
        """All closed-form solutions (up to 8) of a pose (4, 4), ignoring joint ranges.

        Returns (q (6,) wrapped to (-pi, pi], branch Config) pairs in BRANCHES order; [] when
        the pose is out of reach. q_near (6,) only picks the free joints at singularities
        (default zeros). Raises ValueError for a pose that is not a proper rigid transform.
        """
        rows = pose_rows(pose)
        if not is_rigid(rows):
            raise ValueError("pose is not a rigid transform (rotation not proper, or not finite)")
        near = [0.0] * 6 if q_near is None else vector6(q_near, "q_near")
        return [(np.array(q), BRANCHES[b]) for q, b in self._branches(rows, near)]

    def reverse(self, pose, q_near, config: Config = _ANY, joint_min=None, joint_max=None
                ) -> tuple[np.ndarray | None, ReversingResult]:
        """LLI_reverseKin: the joints (6,) reaching `pose` (4, 4) in `config`, within the range.

        SAME fields take q_near's configuration, FREE any. Each joint is moved by whole turns
        to the value closest to q_near inside [joint_min, joint_max] (default: the arm's), which
        matters for J4 and J6 (+-270 deg); among the solutions left, the one closest to q_near
        (Euclidean, rad) wins. Failures return None with: OUT_OF_WORKSPACE (no solution at all),
        OUT_OF_JNT_RANGE (solutions, none in range), INVALID_CONFIG (in range only in other
        configurations), INVALID_ORIENTATION (not a proper rigid transform, NaN or inf).
        Raises ValueError for wrong shapes, non-finite q_near or range, or an unknown config.
        """
        near = vector6(q_near, "q_near")
        lower = self._lower if joint_min is None else vector6(joint_min, "joint_min")
        upper = self._upper if joint_max is None else vector6(joint_max, "joint_max")
        if (joint_min is not None or joint_max is not None) and any(
                lo > hi for lo, hi in zip(lower, upper)):
            raise ValueError("every joint_min must be at most its joint_max")
        rows = pose_rows(pose)
        if not is_rigid(rows):
            return None, ReversingResult.INVALID_ORIENTATION
        allowed = self._allowed_for(config, near)
        # Complete the likeliest branches first and stop once a bound shows the rest are
        # farther: q1, then q1 and q3, then with q5 (each free to turn) underestimate the
        # distance to q_near, so the elbows, q2 and the wrist are computed only where they can
        # still win, and q4, q6 only for the branches fitted.
        n1, n3, n5 = near[0], near[2], near[4]
        rem, two_pi = math.remainder, _TWO_PI
        shoulders = [(rem(s[0] - n1, two_pi) ** 2, s) for s in self._shoulders(rows, near)
                     if not allowed.isdisjoint(_OF_SHOULDER[s[1]])]
        best, best_dist = None, math.inf
        for d1, shoulder in by_bound(shoulders):
            if d1 >= best_dist:
                break
            elbows = [(d1 + rem(e[0] - n3, two_pi) ** 2, e) for e in self._elbows_at(shoulder)
                      if e[1] in allowed or e[1] + 1 in allowed]
            for d13, elbow in by_bound(elbows):
                b = elbow[1]
                if d13 >= best_dist:
                    break
                q1, q2, q3, q5, terms = self._arm(rows, near, elbow)
                positive = d13 + rem(q5 - n5, two_pi) ** 2 if b in allowed else math.inf
                negative = d13 + rem(q5 + n5, two_pi) ** 2 if b + 1 in allowed else math.inf
                order = ((positive, 0), (negative, 1)) if positive <= negative else \
                    ((negative, 1), (positive, 0))
                for bound, wi in order:
                    if bound >= best_dist:
                        break
                    q = [q1, q2, q3, *self._wrist(terms, q5, wi == 1, near)]
                    fitted = fit_range(q, near, lower, upper)
                    if fitted is not None and fitted[1] < best_dist:
                        best, best_dist = fitted
        if best is not None:
            return np.array(best), ReversingResult.OK
        branches = self._branches(rows, near)
        if not branches:
            return None, ReversingResult.OUT_OF_WORKSPACE
        if any(fit_range(q, near, lower, upper) for q, _ in branches):
            return None, ReversingResult.INVALID_CONFIG
        return None, ReversingResult.OUT_OF_JNT_RANGE

    def _allowed_for(self, config: Config, near) -> frozenset[int]:
        """The branch indices a request accepts, SAME fields resolved against q_near."""
        if config is _ANY:
            return _ALL_BRANCHES
        s, e, w = config.shoulder, config.elbow, config.wrist
        if not (s and e and w):   # a SAME field (0): as q_near
            now = self.configuration(near)
            s, e, w = s or now.shoulder, e or now.elbow, w or now.wrist
        code = 16 * s + 4 * e + w if 0 < s < 4 and 0 < e < 4 and 0 < w < 4 else -1
        allowed = _ALLOWED[code] if code >= 0 else None
        if allowed is None:
            raise ValueError(f"not an LLI configuration: {config!r}")
        return allowed

    # ---- inverse, many poses (numpy: kinematics_batch.py) -------------------------------------

    def solve_batch(self, poses, q_near=None) -> np.ndarray:
        """All solutions of many poses: (N, 4, 4) -> (N, 8, 6), NaN where none; q_near (6,)
        or (N, 6). See kinematics_batch.solve_batch."""
        from landscape.robot.kinematics_batch import solve_batch   # it imports this module
        return solve_batch(self, poses, q_near)

