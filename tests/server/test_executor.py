"""The executor's stop and restart along a trajectory (executor.py), without a controller."""
from __future__ import annotations

import numpy as np
import pytest

from landscape.server.executor import _Motion
from landscape.server.motion.timing import time_path
from landscape.server.motion.trajectory import Limits
from landscape.sim.arm import arm_model

DT = 0.004
PATHS = {
    "one joint": [[0, 0, 1.5708, 0, 1.5708, 0], [2.5, 0, 1.5708, 0, 1.5708, 0]],
    "all joints": [[0, 0, 1.5708, 0, 1.5708, 0], [2.5, -0.5, 1.0, 1, 1.0, 2]],
    "blended": [[0, 0, 1.5708, 0, 1.5708, 0], [0.3, 0.2, 1.4, 0.5, 1.2, 0.3],
                [1, -0.3, 1.8, -1, 1.6, 1], [2, 0, 1.0, 0, 0.8, 0]],
}


@pytest.mark.parametrize("name", PATHS)
def test_stopping_and_restarting_anywhere_stays_on_the_path_within_the_limits(name):
    limits = Limits.scaled(arm_model(), 60, 50)
    trajectory = time_path(np.array(PATHS[name], dtype=float), limits, DT)
    for stop_at in range(3, len(trajectory) - 3, 11):
        motion = _Motion({"id": "m", "acceleration": limits.acceleration, "segments": [
            {"positions": trajectory.positions, "velocities": trajectory.velocities}]}, DT)
        commanded, positions = [], []
        for cycle in range(20 * len(trajectory)):
            if cycle == stop_at:
                motion.target_rate = 0.0
            if motion.rate == 0.0 and motion.target_rate == 0.0:
                motion.target_rate = 1.0   # restart as soon as it has stopped
            motion.advance()
            commanded.append(motion.sample(motion.velocities) * motion.rate)
            positions.append(motion.sample(motion.positions))
            if motion.s >= motion.last:
                break
        accel = np.abs(np.diff(commanded, axis=0)) / DT
        assert np.all(accel <= limits.acceleration * (1 + 1e-9)), (stop_at, accel.max(axis=0))
        assert np.allclose(positions[-1], trajectory.positions[-1])   # it went on to the end
        assert min(np.abs(np.asarray(commanded)).sum(axis=1)[stop_at:]) < 1e-9  # it did stop
