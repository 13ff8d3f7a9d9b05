"""Fixtures for the collision tests: the default cell, a fresh scene, and motions planned by the
server's own Planner (time_path), so the checks see the trajectories the device would play."""
from __future__ import annotations

import numpy as np
import pytest

from landscape.server.planning.collision import CollisionScene, check_motion
from landscape.server.planning.moves import Planner
from landscape.server.device.motion_settings import MotionSettings
from landscape.robot.units import pose_matrix
from landscape.robot.cell import load_cell
from landscape.robot.kinematics import Kinematics

DOWN = (np.pi, 0.0, 0.0)   # flange pointing down


class Cellkit:
    """The default cell with its planner: joints for flange positions, planned motions, and
    their check against a scene."""

    def __init__(self):
        self.cell = load_cell()
        self.kin = Kinematics(self.cell.arm)
        self.planner = Planner(self.kin, self.cell.controller.cycle_time)
        self.limits = self.planner.limits(
            MotionSettings(self.cell.arm, speed_percent=50, accel_percent=100), None)
        self.q0 = np.array(self.cell.controller.initial_position)

    def ik(self, xyz, near=None, rpy=DOWN) -> np.ndarray:
        """Joints putting the flange at xyz (m) with fixed-axis angles rpy, nearest `near`."""
        return self.joints(pose_matrix(xyz, rpy), near)

    def joints(self, flange: np.ndarray, near=None) -> np.ndarray:
        q, result = self.kin.reverse(flange, self.q0 if near is None else near)
        assert q is not None, result
        return q

    def plan(self, waypoints):
        """The trajectory through the waypoints (M, 6) as the Planner times a path (M = 2: a
        joint move), marks at every waypoint."""
        return self.planner.timed(np.array(waypoints, dtype=float), self.limits)

    def check(self, scene: CollisionScene, waypoints, **options):
        trajectory = self.plan(waypoints)
        return check_motion(scene.model(), trajectory.positions, trajectory.dt,
                            trajectory.marks, **options)


@pytest.fixture(scope="session")
def kit() -> Cellkit:
    return Cellkit()


@pytest.fixture
def scene(kit) -> CollisionScene:
    return CollisionScene(kit.cell)
