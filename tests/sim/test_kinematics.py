"""sim/kinematics.py: forward kinematics against pinocchio, closed-form IK round trips,
configuration labels, reverse() and its LLI reversing results, singular poses."""
from __future__ import annotations

import math
import subprocess
import sys
import warnings

import numpy as np
import pytest

from landscape.robot.arm import VARIANTS, ArmModel, arm_model
from landscape.robot.kinematics import (BRANCHES, Config, Kinematics, PosNeg, ReversingResult,
                                      Shoulder, wrap_angle)
from landscape.robot.pinocchio_model import PinocchioModel

TX90 = arm_model()
TOL_POS = 1e-12  # m: the closed form is exact to rounding
TOL_ROT = 1e-12  # rad
OK = ReversingResult.OK


@pytest.fixture(scope="module")
def kin() -> Kinematics:
    return Kinematics(TX90)


def random_joints(arm: ArmModel, n: int, seed: int) -> np.ndarray:
    return np.random.default_rng(seed).uniform(arm.lower, arm.upper, (n, 6))


def pose_errors(Ta: np.ndarray, Tb: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position error (m) and rotation angle between (rad) of (..., 4, 4) poses.

    The angle comes from the chord |Ra - Rb|_F = 2 sqrt(2) sin(angle / 2), which stays accurate
    near zero (unlike acos of the trace)."""
    pos = np.linalg.norm(Ta[..., :3, 3] - Tb[..., :3, 3], axis=-1)
    chord = np.linalg.norm(Ta[..., :3, :3] - Tb[..., :3, :3], axis=(-2, -1))
    return pos, 2.0 * np.arcsin(np.minimum(1.0, chord / (2.0 * math.sqrt(2.0))))


def assert_reaches(kin: Kinematics, q, T) -> None:
    pos, rot = pose_errors(kin.forward(q), T)
    assert np.all(pos < TOL_POS) and np.all(rot < TOL_ROT), (pos.max(), rot.max())


def wrist_centre_x_link1(arm: ArmModel, q: np.ndarray, T: np.ndarray) -> np.ndarray:
    """x of the wrist centre in the frame of link 1 (J1 turned by q1), from the pose alone:
    the label test's own geometry, independent of the solver's."""
    centre = T[..., :3, 3] - arm.c4 * T[..., :3, 2]
    return np.cos(q[..., 0]) * centre[..., 0] + np.sin(q[..., 0]) * centre[..., 1]


def check_round_trip(kin: Kinematics, Q: np.ndarray) -> None:
    """All batch solutions reach the pose, carry labels matching their signs, and include Q."""
    arm = kin.arm
    T = kin.forward(Q)
    S = kin.solve_batch(T)
    assert S.shape == (len(Q), 8, 6)
    found = ~np.isnan(S[..., 0])
    assert np.array_equal(found[..., None].repeat(6, -1), ~np.isnan(S))   # whole solutions or none
    sols, poses = S[found], np.broadcast_to(T[:, None], S.shape[:2] + (4, 4))[found]
    assert np.all((sols > -math.pi) & (sols <= math.pi))
    assert_reaches(kin, sols, poses)

    # The labels name the signs: shoulder by the wrist centre's side of J1, elbow q3, wrist q5.
    branch = np.broadcast_to(np.arange(8), found.shape)[found]
    labels = np.array([[b.shoulder, b.elbow, b.wrist] for b in BRANCHES])[branch]
    righty = wrist_centre_x_link1(arm, sols, poses) >= 0
    # The elbow's sign is the bend between upper arm and forearm (a2 offsets the forearm at
    # the elbow): q3 itself when a2 = 0.
    bend = wrap_angle(sols[:, 2] + math.atan2(arm.a2, arm.c3))
    assert np.array_equal(labels[:, 0] == Shoulder.RIGHTY, righty)
    assert np.array_equal(labels[:, 1] == PosNeg.POSITIVE, bend >= 0)
    assert np.array_equal(labels[:, 2] == PosNeg.POSITIVE, sols[:, 4] >= 0)
    for q, b in zip(sols[:400], branch[:400]):           # the scalar labeller agrees
        assert kin.configuration(q) == BRANCHES[b]

    # The original joints are the solution of their own branch, modulo whole turns.
    own = np.array([BRANCHES.index(kin.configuration(q)) for q in Q])
    assert np.all(np.abs(wrap_angle(S[np.arange(len(Q)), own] - Q)) < 1e-8)


# ---- forward --------------------------------------------------------------------------------

def test_home_pose_is_the_published_one(kin):
    T = kin.forward(np.zeros(6))
    assert np.allclose(T[:3, 3], (0.05, 0.05, 1.428), atol=1e-15)
    assert np.allclose(T[:3, :3], np.eye(3), atol=1e-15)


@pytest.mark.parametrize("variant", sorted(VARIANTS))
def test_forward_matches_pinocchio(variant):
    arm = arm_model(variant)
    kin, pin_model = Kinematics(arm), PinocchioModel(arm)
    Q = random_joints(arm, 300, seed=1)
    batch = kin.forward(Q)
    for q, T in zip(Q, batch):
        expected = pin_model.forward(q)
        pos, rot = pose_errors(T, expected)
        assert pos < TOL_POS and rot < TOL_ROT
        assert np.array_equal(kin.forward(q), T)       # scalar and batched paths agree


def test_jacobian_matches_finite_differences(kin):
    pin_model = PinocchioModel(TX90)
    h = 1e-6
    for q in random_joints(TX90, 20, seed=2):
        J = pin_model.jacobian(q)
        assert J.shape == (6, 6)
        for i in range(6):
            dq = np.zeros(6)
            dq[i] = h
            Tp, Tm = kin.forward(q + dq), kin.forward(q - dq)
            linear = (Tp[:3, 3] - Tm[:3, 3]) / (2 * h)
            W = (Tp[:3, :3] - Tm[:3, :3]) / (2 * h) @ kin.forward(q)[:3, :3].T   # skew(omega)
            angular = np.array([W[2, 1], W[0, 2], W[1, 0]])
            assert np.allclose(J[:3, i], linear, atol=1e-7)
            assert np.allclose(J[3:, i], angular, atol=1e-7)


# ---- inverse: round trips -------------------------------------------------------------------

def test_round_trip_10000_random_joints(kin):
    check_round_trip(kin, random_joints(TX90, 10_000, seed=3))


@pytest.mark.parametrize("arm", [arm_model("TX90L"), arm_model("TX90XL"),
                                 arm_model(a2=0.03, b=-0.02)], ids=["TX90L", "TX90XL", "offsets"])
def test_round_trip_other_geometries(arm):
    check_round_trip(Kinematics(arm), random_joints(arm, 1_000, seed=4))


def test_scalar_path_matches_batch_and_returns_the_original(kin):
    Q = random_joints(TX90, 10_000, seed=5)
    T = kin.forward(Q)
    scalar = np.full((len(Q), 8, 6), np.nan)
    reversed_ = np.full((len(Q), 6), np.nan)
    for i, (q, pose) in enumerate(zip(Q, T)):
        for s, c in kin.solutions(pose):
            scalar[i, BRANCHES.index(c)] = s
            assert kin.configuration(s) == c
        result, code = kin.reverse(pose, q)
        assert code == OK
        reversed_[i] = result
    batch = kin.solve_batch(T)
    assert np.array_equal(np.isnan(scalar), np.isnan(batch))
    found = ~np.isnan(batch)
    # Exact to rounding, except that near the wrist singularity a few ulps of the wrist's
    # rotation become (ulps / |sin q5|) in joints 4 and 6, and the two paths round differently.
    wrist = np.zeros(6)
    wrist[[3, 5]] = 1e-14
    tolerance = 1e-12 + wrist / np.maximum(np.abs(np.sin(batch[..., 4:5])), 1e-300)
    assert np.all(np.abs(scalar - batch)[found] <= tolerance[found])
    assert np.allclose(reversed_, Q, atol=1e-9, rtol=0)


# ---- reverse: configurations and ranges -----------------------------------------------------

def in_range_modulo_turns(q, lower, upper) -> bool:
    k_low = np.ceil((lower - 1e-10 - q) / (2 * math.pi))
    return bool(np.all(q + 2 * math.pi * k_low <= upper + 1e-10))


def test_reverse_specific_configurations(kin):
    for q in random_joints(TX90, 200, seed=6):
        pose = kin.forward(q)
        batch = kin.solve_batch(pose[None])[0]
        near = q + 0.1
        results = []
        for b, config in enumerate(BRANCHES):
            result, code = kin.reverse(pose, near, config)
            exists = not np.isnan(batch[b, 0])
            if exists and in_range_modulo_turns(batch[b], TX90.lower, TX90.upper):
                assert code == OK and kin.configuration(result) == config
                assert np.all((result >= TX90.lower) & (result <= TX90.upper))
                assert_reaches(kin, result, pose)
                results.append(result)
            else:
                assert result is None and code == ReversingResult.INVALID_CONFIG
        # FREE picks the nearest of them; SAME the one in q_near's configuration.
        free, code = kin.reverse(pose, near)
        assert code == OK
        nearest = min(np.linalg.norm(r - near) for r in results)
        assert np.linalg.norm(free - near) == pytest.approx(nearest)
        same, code = kin.reverse(pose, q, Config(Shoulder.SAME, PosNeg.SAME, PosNeg.SAME))
        assert code == OK and np.allclose(same, q, atol=1e-9)


def test_reverse_same_follows_q_near_per_field(kin):
    q = np.array([0.4, 0.3, 1.2, 0.5, 0.8, -0.3])
    pose = kin.forward(q)
    other = dict((c, s) for s, c in kin.solutions(pose))[Config(Shoulder.RIGHTY, PosNeg.NEGATIVE,
                                                                 PosNeg.NEGATIVE)]
    # SAME elbow and wrist from `other`, shoulder given explicitly.
    result, code = kin.reverse(pose, other, Config(Shoulder.RIGHTY, PosNeg.SAME, PosNeg.SAME))
    assert code == OK and kin.configuration(result) == kin.configuration(other)
    assert np.allclose(result, other, atol=1e-9)


def test_reverse_picks_the_turn_of_j4_j6_nearest_q_near(kin):
    q = np.array([0.2, 0.4, 1.0, 4.0, 0.9, -4.2])       # J4, J6 beyond +-pi, within +-270 deg
    pose = kin.forward(q)
    result, code = kin.reverse(pose, q)
    assert code == OK and np.allclose(result, q, atol=1e-9)
    near = q.copy()
    near[3] -= 2 * math.pi
    near[5] += 2 * math.pi
    result, code = kin.reverse(pose, near)
    assert code == OK and np.allclose(result, near, atol=1e-9)
    # Narrow J4 to exclude 4.0: the other turn is taken even with q_near at 4.0.
    upper = TX90.upper.copy()
    upper[3] = 3.0
    same = Config(Shoulder.SAME, PosNeg.SAME, PosNeg.SAME)
    result, code = kin.reverse(pose, q, same, joint_max=upper)
    assert code == OK and result[3] == pytest.approx(4.0 - 2 * math.pi)


# ---- reverse: reversing results -------------------------------------------------------------

def test_out_of_workspace(kin):
    far = np.eye(4)
    far[:3, 3] = (3.0, 0.0, 0.5)
    assert kin.reverse(far, np.zeros(6)) == (None, ReversingResult.OUT_OF_WORKSPACE)
    # Wrist centre on the J1 axis: closer to it than the lateral offset b allows.
    axis = np.eye(4)
    axis[:3, 3] = (0.0, 0.0, 1.0)
    assert kin.reverse(axis, np.zeros(6)) == (None, ReversingResult.OUT_OF_WORKSPACE)
    assert kin.solutions(far) == [] and np.isnan(kin.solve_batch(far[None])).all()


def test_out_of_joint_range(kin):
    q = np.array([1.0, 0.3, 0.8, 0.5, 0.7, 0.2])
    pose = kin.forward(q)
    lower, upper = TX90.lower.copy(), TX90.upper.copy()
    lower[0], upper[0] = -0.2, 0.2
    assert all(abs(s[0]) > 0.2 for s, _ in kin.solutions(pose))   # no branch has J1 in range
    assert kin.reverse(pose, q, joint_min=lower, joint_max=upper) == (
        None, ReversingResult.OUT_OF_JNT_RANGE)


def test_invalid_config(kin):
    q = np.array([1.0, -0.3, -0.6, 0.5, 0.7, 0.2])       # LEFTY; RIGHTY has q1 near -2.4
    pose = kin.forward(q)
    assert kin.configuration(q).shoulder == Shoulder.LEFTY
    # RIGHTY exists here, but only with J1 outside a range that keeps the LEFTY solutions.
    lower, upper = TX90.lower.copy(), TX90.upper.copy()
    lower[0], upper[0] = 0.9, 1.1
    righty, lefty = Config(shoulder=Shoulder.RIGHTY), Config(shoulder=Shoulder.LEFTY)
    assert kin.reverse(pose, q, righty)[1] == OK
    assert kin.reverse(pose, q, righty, lower, upper) == (None, ReversingResult.INVALID_CONFIG)
    assert kin.reverse(pose, q, lefty, lower, upper)[1] == OK
    # Reaching far forward, the LEFTY branches do not exist at all (J2 is ahead of J1).
    reach = np.array([0.0, 1.2, 0.3, 0.0, 0.0, 0.0])
    pose = kin.forward(reach)
    assert {c.shoulder for _, c in kin.solutions(pose)} == {Shoulder.RIGHTY}
    assert kin.reverse(pose, reach, lefty) == (None, ReversingResult.INVALID_CONFIG)


def bad_poses(kin):
    good = kin.forward(np.array([0.3, 0.2, 0.9, 0.4, 0.6, 0.1]))
    scaled = good.copy()
    scaled[:3, :3] *= 1.01
    mirrored = good.copy()
    mirrored[:3, 0] *= -1.0                             # orthonormal, determinant -1
    sheared = good.copy()
    sheared[:3, 1] += 1e-3 * sheared[:3, 0]
    bottom = good.copy()
    bottom[3, 3] = 2.0
    nan_rot = good.copy()
    nan_rot[1, 1] = np.nan
    inf_pos = good.copy()
    inf_pos[0, 3] = np.inf
    return {"scaled": scaled, "mirrored": mirrored, "sheared": sheared, "bottom": bottom,
            "nan": nan_rot, "inf": inf_pos}


def test_invalid_orientation(kin):
    for name, pose in bad_poses(kin).items():
        assert kin.reverse(pose, np.zeros(6)) == (None, ReversingResult.INVALID_ORIENTATION), name
        with pytest.raises(ValueError):
            kin.solutions(pose)


def test_solve_batch_marks_bad_poses_nan_without_warnings(kin):
    good = kin.forward(random_joints(TX90, 3, seed=7))
    poses = np.concatenate([good, np.stack(list(bad_poses(kin).values()))])
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        S = kin.solve_batch(poses)
    assert not np.isnan(S[:3, 0]).all(axis=-1).any()
    assert np.isnan(S[3:]).all()


def test_bad_arguments_raise_value_error(kin):
    pose = kin.forward(np.zeros(6))
    with pytest.raises(ValueError):
        kin.reverse(pose[:3], np.zeros(6))
    with pytest.raises(ValueError):
        kin.reverse(pose, np.zeros(5))
    with pytest.raises(ValueError):
        kin.reverse(pose, np.full(6, np.nan))
    with pytest.raises(ValueError):
        kin.reverse(pose, np.zeros(6), joint_min=TX90.upper, joint_max=TX90.lower)
    with pytest.raises(ValueError):
        kin.reverse(pose, np.zeros(6), Config(7, 1, 1))
    with pytest.raises(ValueError):
        kin.solve_batch(pose)
    with pytest.raises(ValueError):
        kin.forward(np.zeros(5))


# ---- singular poses -------------------------------------------------------------------------

def assert_all_solutions_reach(kin, pose, q_near=None):
    sols = kin.solutions(pose, q_near)
    assert sols and all(np.all(np.isfinite(s)) for s, _ in sols)
    for s, _ in sols:
        assert_reaches(kin, s, pose)
    return sols


def test_wrist_singularity_takes_q4_from_q_near(kin):
    q = np.array([0.3, 0.2, 0.9, 1.2, 0.0, -0.4])
    pose = kin.forward(q)
    assert len(assert_all_solutions_reach(kin, pose, q)) == 8
    result, code = kin.reverse(pose, q)
    assert code == OK and np.allclose(result, q, atol=1e-9)
    near = q.copy()
    near[3] = -0.5
    result, code = kin.reverse(pose, near)
    assert code == OK and result[3] == pytest.approx(-0.5)
    assert result[5] == pytest.approx(-0.4 + 1.7)              # q4 + q6 is what the pose fixes
    assert_reaches(kin, result, pose)
    # Both wrist labels are met at q5 = 0.
    for wrist in (PosNeg.POSITIVE, PosNeg.NEGATIVE):
        result, code = kin.reverse(pose, near, Config(Shoulder.SAME, PosNeg.SAME, wrist))
        assert code == OK and result[3] == pytest.approx(-0.5)
    # q5 = pi (outside J5's range, but a closed-form solution all the same).
    flipped = kin.forward(np.array([0.3, 0.2, 0.9, 1.2, math.pi, -0.4]))
    assert_all_solutions_reach(kin, flipped)


def test_stretched_arm_and_home(kin):
    q = np.array([0.5, 0.7, 0.0, 0.3, 0.6, 0.2])        # q3 = 0: arm stretched
    pose = kin.forward(q)
    sols = dict((c, s) for s, c in assert_all_solutions_reach(kin, pose))
    up, down = (Config(Shoulder.RIGHTY, elbow, PosNeg.POSITIVE)
                for elbow in (PosNeg.POSITIVE, PosNeg.NEGATIVE))
    assert np.allclose(sols[up], sols[down], atol=1e-7)
    for elbow in (PosNeg.POSITIVE, PosNeg.NEGATIVE):
        result, code = kin.reverse(pose, q, Config(Shoulder.SAME, elbow, PosNeg.SAME))
        assert code == OK and np.allclose(result, q, atol=1e-7)
    home = kin.forward(np.zeros(6))                     # stretched and wrist-singular at once
    assert_all_solutions_reach(kin, home)
    result, code = kin.reverse(home, np.zeros(6))
    assert code == OK and np.allclose(result, 0.0, atol=1e-7)


def test_shoulder_singularity(kin):
    # Wrist centre in the plane of J1 and the lateral offset (x = 0 in link 1).
    q = np.array([0.4, 0.0, -math.asin(TX90.a1 / TX90.c3), 0.3, 0.6, 0.2])
    pose = kin.forward(q)
    assert abs(wrist_centre_x_link1(TX90, q, pose)) < 1e-12
    sols = assert_all_solutions_reach(kin, pose)
    assert {c.shoulder for _, c in sols} == {Shoulder.RIGHTY, Shoulder.LEFTY}
    for shoulder in (Shoulder.RIGHTY, Shoulder.LEFTY):
        result, code = kin.reverse(pose, q, Config(shoulder, PosNeg.SAME, PosNeg.SAME))
        assert code == OK and np.allclose(result, q, atol=1e-6)


def test_wrist_centre_on_j1_axis_and_on_j2():
    # Without a lateral offset the wrist centre can sit on the J1 axis: q1 comes from q_near.
    arm = arm_model(b=0.0)
    kin = Kinematics(arm)
    q = np.array([0.7, 0.0, -math.asin(arm.a1 / arm.c3), 0.3, 0.6, 0.2])
    pose = kin.forward(q)
    assert_all_solutions_reach(kin, pose, q)
    result, code = kin.reverse(pose, q)
    assert code == OK and result[0] == pytest.approx(0.7)
    # c2 = c3 and q3 = pi fold the wrist centre onto J2: q2 is free (solutions only; J3 can't).
    folded = kin.forward(np.array([0.2, 0.5, math.pi, 0.1, 0.4, 0.3]))
    assert_all_solutions_reach(kin, folded, np.zeros(6))


# ---- the rest -------------------------------------------------------------------------------

def test_unsupported_geometry_is_refused():
    class OffsetWrist(ArmModel):
        @property
        def joint_origins(self):
            origins = list(super().joint_origins)
            origins[5] = (0.01, 0.0, self.c4)           # J6 off the wrist centre
            return tuple(origins)

    with pytest.raises(ValueError):
        Kinematics(OffsetWrist())


def test_pinocchio_dls_agrees_with_closed_form(kin):
    pin_model = PinocchioModel(TX90)
    rng = np.random.default_rng(8)
    for q in random_joints(TX90, 5, seed=8):
        pose = kin.forward(q)
        seed = q + rng.uniform(-0.1, 0.1, 6)
        numeric, converged, _ = pin_model.ik_dls(pose, seed)
        assert converged
        closed, code = kin.reverse(pose, seed)
        assert code == OK and np.allclose(wrap_angle(numeric - closed), 0.0, atol=1e-8)


def test_module_imports_without_pinocchio():
    code = ("import sys, landscape.robot.kinematics; "
            "sys.exit('pinocchio' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code], timeout=60).returncode == 0
