"""Poses and their roll, pitch, yaw: the fixed-axis X-Y-Z convention of DESIGN section 6,
R = Rz(yaw) Ry(pitch) Rx(roll), both ways, on random rotations and on the boundaries (gimbal
lock, +-pi) where a conversion can pick other angles than the ones the replies carry."""
from __future__ import annotations

import math

import numpy as np
import pytest

from landscape.robot.units import AngularUnit, LinearUnit, Units, matrix_rpy, pose_matrix

BOUNDARY = [math.pi, -math.pi, math.pi / 2, -math.pi / 2, 0.0, -0.0, math.pi - 1e-12,
            math.pi / 2 - 1e-11, -math.pi / 2 + 1e-7, 1.5707963, 1e-17]


def _about(axis: int, angle: float) -> np.ndarray:
    """The elementary rotation about x (0), y (1) or z (2), written out."""
    c, s = math.cos(angle), math.sin(angle)
    j, k = (axis + 1) % 3, (axis + 2) % 3
    r = np.eye(3)
    r[j, j], r[j, k], r[k, j], r[k, k] = c, -s, s, c
    return r


def _angles():
    rng = np.random.default_rng(7)
    yield from rng.uniform(-4.0, 4.0, (2000, 3))
    yield from ((a, b, c) for a in BOUNDARY for b in BOUNDARY for c in BOUNDARY)


def test_a_pose_turns_about_the_fixed_x_then_y_then_z():
    for roll, pitch, yaw in _angles():
        expected = _about(2, yaw) @ _about(1, pitch) @ _about(0, roll)
        assert np.abs(pose_matrix((1, 2, 3), (roll, pitch, yaw))[:3, :3] - expected).max() < 1e-12


def test_roll_pitch_yaw_give_back_the_rotation_with_pitch_in_range():
    for angles in _angles():
        rotation = pose_matrix((0, 0, 0), angles)[:3, :3]
        rpy = matrix_rpy(rotation)
        assert -math.pi / 2 <= rpy[1] <= math.pi / 2
        assert np.all(np.abs(rpy) <= math.pi)
        assert np.abs(pose_matrix((0, 0, 0), rpy)[:3, :3] - rotation).max() < 1e-12


@pytest.mark.parametrize("pitch", [math.pi / 2, -math.pi / 2])
def test_at_gimbal_lock_the_roll_is_zero_and_the_yaw_carries_the_turn(pitch):
    rotation = pose_matrix((0, 0, 0), (0.4, pitch, 1.1))[:3, :3]
    roll, got_pitch, yaw = matrix_rpy(rotation)
    assert roll == 0.0 and got_pitch == pytest.approx(pitch, abs=1e-12)
    assert np.abs(pose_matrix((0, 0, 0), (0.0, got_pitch, yaw))[:3, :3] - rotation).max() < 1e-12


def test_a_tool_pointing_down_reads_roll_pi():
    """The usual pose of a tool over the table: its replies say roll pi, not -pi."""
    rpy = matrix_rpy(pose_matrix((0, 0, 0), (math.pi, 0.0, 0.3))[:3, :3])
    assert rpy == pytest.approx([math.pi, 0.0, 0.3], abs=1e-12) and rpy[0] > 0


def test_units_apply_at_the_edge_only():
    units = Units(LinearUnit.MILLIMETERS, AngularUnit.DEGREES)
    matrix = units.pose_to_matrix([100.0, -20.0, 300.0, 180.0, 0.0, 90.0])
    assert np.allclose(matrix, pose_matrix((0.1, -0.02, 0.3), (math.pi, 0.0, math.pi / 2)),
                       atol=1e-15)
    assert units.matrix_to_pose(matrix) == pytest.approx([100.0, -20.0, 300.0, 180.0, 0.0, 90.0])
