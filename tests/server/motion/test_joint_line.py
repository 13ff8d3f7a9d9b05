"""server/planning/joint_line.py: a joint move timed by ruckig along the straight joint line,
checked on its samples as the cycle plays them: on the line, exact ends at rest, velocity,
acceleration and jerk within the limits (the samples held at rest before and after), and
never slower than TOPP-RA's jerk-limited timing of the same line (timing.time_path)."""
from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from landscape.robot.arm import arm_model
from landscape.robot.kinematics import Kinematics
from landscape.server.device.motion_settings import MotionSettings
from landscape.server.errors import OutOfRange
from landscape.server.planning.joint_line import time_joint_line
from landscape.server.planning.motion.timing import LIMIT_SLACK, time_path
from landscape.server.planning.motion.trajectory import Limits
from landscape.server.planning.moves import Planner

ARM = arm_model()
DT = 0.004


def limits(speed: float = 100.0, accel: float = 100.0) -> Limits:
    return Limits.scaled(ARM, speed, accel)


def pairs(count: int, seed: int):
    rng = np.random.default_rng(seed)
    for _ in range(count):
        yield (rng.uniform(0.6 * ARM.lower, 0.6 * ARM.upper),
               rng.uniform(0.6 * ARM.lower, 0.6 * ARM.upper))


def held(positions: np.ndarray) -> np.ndarray:
    """The samples with three cycles at rest before and after, as the drives see a move."""
    return np.vstack([positions[:1]] * 3 + [positions] + [positions[-1:]] * 3)


@pytest.mark.parametrize("speed, accel", [(100, 100), (20, 100), (100, 10), (5, 50)])
def test_every_sample_keeps_the_limits_on_the_line_with_exact_ends(speed, accel):
    lim = limits(speed, accel)
    for q0, q1 in pairs(20, seed=int(speed * 7 + accel)):
        move = time_joint_line(q0, q1, lim, DT, 30.0)
        q = held(move.positions)
        assert np.array_equal(move.positions[0], q0) and np.allclose(move.positions[-1], q1,
                                                                     atol=1e-12)
        assert not move.velocities[0].any() and not move.velocities[-1].any()
        assert move.marks == ((0, 0), (len(move) - 1, 1))
        along = (move.positions - q0) @ (q1 - q0) / np.dot(q1 - q0, q1 - q0)
        assert np.allclose(move.positions, q0 + along[:, None] * (q1 - q0), atol=1e-12)
        assert np.all(np.diff(along) >= -1e-12)          # forward only
        for value, limit in ((np.abs(move.velocities), lim.velocity),
                             (np.abs(np.diff(q, 2, axis=0)) / DT**2, lim.acceleration),
                             (np.abs(np.diff(q, 3, axis=0)) / DT**3, lim.jerk)):
            assert (value / limit).max() <= 1.0 + LIMIT_SLACK


def test_it_is_never_slower_than_toppra_timing_of_the_same_line():
    lim = limits()
    for q0, q1 in pairs(30, seed=3):
        ruckig = time_joint_line(q0, q1, lim, DT, 30.0)
        toppra = time_path(np.array([q0, q1]), lim, DT)
        assert len(ruckig) <= len(toppra), (len(ruckig), len(toppra))


def test_no_motion_or_no_jerk_limit_is_left_to_time_path():
    q = np.array([0.0, 0.3, 1.4, 0.0, 0.9, 0.0])
    assert time_joint_line(q, q, limits(), DT, 30.0) is None
    assert time_joint_line(q, q + 0.1, dataclasses.replace(limits(), jerk=None), DT, 30.0) is None


def test_the_planner_refuses_a_joint_move_longer_than_allowed():
    planner = Planner(Kinematics(ARM), DT)
    q0 = np.array([-2.0, 0.3, 1.4, 0.0, 0.9, 0.0])
    with pytest.raises(OutOfRange):
        planner.joint_move(q0, q0 * [-1, 1, 1, 1, 1, 1], planner.limits(MotionSettings(ARM), 1.0),
                           max_duration=0.5)
