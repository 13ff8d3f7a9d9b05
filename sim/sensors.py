"""The cell's sensors, computed by the simulation and read on demand (nothing per cycle).

- `ForceTorqueSensor` ("force_sensor", LandScape 3.7.1): six-axis, between the flange and the
  tool changer: pybullet's joint force/torque sensor on the fixed joint link6 -> tool0, so it
  feels the mounted tool's weight and inertia and every contact on the tool or a held part, but
  nothing that touches the arm itself.
- `LaserRangeSensor` ("laser_standoff_sensor"): a ray along the tool axis from the tool tip.

Each `read()` returns a float numpy array; shapes and units on the classes.
"""
from __future__ import annotations

import math

import numpy as np

from landscape.robot.cell import SensorSpec
from landscape.sim.tools import rotation
from landscape.sim.world import World


class ForceTorqueSensor:
    """read() -> (6,) [Fx, Fy, Fz (N), Mx, My, Mz (N*m)]: the wrench the tool side exerts on
    the flange, torques about the flange origin, in the sensor frame = the flange frame tool0
    (z along the tool axis, away from the arm). With the tool pointing down, a tool of mass m
    reads Fz = +m*g; pushing the tool against something reads Fz < 0. tare() makes the present
    reading zero (until the next tare); the reading is that of the last physics step.
    """

    def __init__(self, world: World, spec: SensorSpec):
        self.name = spec.name
        self._bc, self._arm, self._joint = world.bc, world.arm, world.flange_joint
        self._bc.enableJointForceTorqueSensor(self._arm, self._joint, True)
        self._offset = np.zeros(6)

    def raw(self) -> np.ndarray:
        # pybullet reports what the parent (link6) exerts on the child (tool0), in the child's
        # frame: the opposite of the load the tool puts on the flange.
        return -np.array(self._bc.getJointState(self._arm, self._joint)[2])

    def read(self) -> np.ndarray:
        return self.raw() - self._offset

    def tare(self) -> None:
        self._offset = self.raw()


class LaserRangeSensor:
    """read() -> (1,) [range (m)]: distance along the tool axis (+z of the tool tip frame; of the
    flange when no tool is mounted) from the tip, moved by `offset` in that frame, to the first
    surface hit. The beam starts at min_range (closer surfaces, such as a part held at the tip,
    are not seen) and ends at max_range: with no surface in between the reading is NaN.
    """

    def __init__(self, world: World, spec: SensorSpec):
        self.name = spec.name
        self._world = world
        self.min_range, self.max_range = spec.min_range, spec.max_range
        self._offset = np.asarray(spec.offset, dtype=float)

    def read(self) -> np.ndarray:
        pos, orn = self._world.tip_pose()
        r = rotation(orn)
        origin = np.asarray(pos) + r @ self._offset
        axis = r[:, 2]
        hit = self._world.bc.rayTest((origin + self.min_range * axis).tolist(),
                                     (origin + self.max_range * axis).tolist())[0]
        if hit[0] < 0:
            return np.array([math.nan])
        return np.array([self.min_range + hit[2] * (self.max_range - self.min_range)])

    def tare(self) -> None:
        """A range sensor has nothing to zero."""


SENSOR_CLASSES = {"force_torque": ForceTorqueSensor, "laser_range": LaserRangeSensor}
