"""The six-axis force/torque sensor at the flange and the laser standoff sensor on the tool axis."""
from __future__ import annotations

import math
import sys
from pathlib import Path

import numpy as np
import pytest

from landscape.robot.controller import EnableState

sys.path.insert(0, str(Path(__file__).parent))
from bullet_helpers import (DEFAULT_CELL, controller, joints_for, matrix,  # noqa: E402
                            mount_tool, move_to, run)

G = 9.81
TABLE_TOP = 0.2
FREE_SPOT = (0.7, 0.3)                   # on the table, away from the parts
DOWN = np.diag([1.0, -1.0, -1.0, 1.0])


def over_table(z: float) -> np.ndarray:
    """Flange pose pointing down over the free spot of the table, flange at height z (m)."""
    pose = DOWN.copy()
    pose[:3, 3] = (*FREE_SPOT, z)
    return pose


def test_sensors_are_listed_and_unknown_names_fail():
    ctrl = controller(enabled=False)
    assert sorted(s.name for s in ctrl.sensor_map()) == ["force_sensor", "laser_standoff_sensor"]
    assert ctrl.read_sensor("force_sensor").shape == (6,)
    assert ctrl.read_sensor("laser_standoff_sensor").shape == (1,)
    with pytest.raises(KeyError, match="no sensor"):
        ctrl.read_sensor("sonar")


def test_force_sensor_reads_the_tool_weight_then_a_contact():
    ctrl = controller()
    run(ctrl, 0.05)
    assert np.abs(ctrl.read_sensor("force_sensor")).max() < 1e-3       # nothing on the flange
    mount_tool(ctrl, "vacuum")
    tool = ctrl.world.mounted.spec
    run(ctrl, 0.1)
    wrench = ctrl.read_sensor("force_sensor")
    print(f"\nF/T with the {tool.mass} kg cup pointing down: {np.round(wrench, 4)}")
    assert wrench[:3] == pytest.approx([0.0, 0.0, tool.mass * G], abs=0.01 * tool.mass * G)
    assert np.abs(wrench[3:]).max() < 1e-3                          # its centre is on the axis

    ctrl.tare_sensor("force_sensor")
    assert np.abs(ctrl.read_sensor("force_sensor")).max() < 1e-9
    # Tip 5 cm above the table, then pressed into it: the table pushes back along -z of the
    # sensor, the more the deeper (the cup's contact is compliant, cell contact_stiffness).
    move_to(ctrl, joints_for(ctrl, over_table(TABLE_TOP + tool.length + 0.05)), 1.2)
    assert np.abs(ctrl.read_sensor("force_sensor")).max() < 0.5          # inertia only, at rest
    pressing = []
    for depth in (0.001, 0.003):
        move_to(ctrl, joints_for(ctrl, over_table(TABLE_TOP + tool.length - depth)), 0.4,
                settle=0.2)
        pressing.append(ctrl.read_sensor("force_sensor"))
    print(f"F/T pressing 1 and 3 mm into the table: {np.round(pressing, 2).tolist()}")
    light, firm = pressing
    assert -200.0 < firm[2] < light[2] < -5.0
    assert np.abs(firm[:2]).max() < 0.2 * abs(firm[2])       # some friction sideways
    assert ctrl.state().enable is EnableState.ENABLED
    move_to(ctrl, joints_for(ctrl, over_table(TABLE_TOP + tool.length + 0.05)), 0.6)
    assert np.abs(ctrl.read_sensor("force_sensor")).max() < 0.5          # free again


def test_laser_range_matches_the_geometry():
    ctrl = controller()
    flange_z = ctrl.world.flange_pose()[0][2]
    no_tool = ctrl.read_sensor("laser_standoff_sensor")[0]
    assert no_tool == pytest.approx(flange_z - TABLE_TOP, abs=1e-3)   # no tool: from the flange

    mount_tool(ctrl, "gripper")                  # now from the finger tips, 0.16 m further
    ranges = []
    for z in (0.75, 0.6, 0.45, 0.38):
        move_to(ctrl, joints_for(ctrl, over_table(z)), 0.6)
        tip_z = ctrl.world.tip_pose()[0][2]
        assert tip_z == pytest.approx(z - 0.16, abs=1e-4)
        reading = ctrl.read_sensor("laser_standoff_sensor")[0]
        ranges.append(reading)
        assert reading == pytest.approx(tip_z - TABLE_TOP, abs=2e-3)
    assert ranges == sorted(ranges, reverse=True)
    print(f"\nlaser ranges as the gripper approaches the table: {np.round(ranges, 5)} m")


def test_laser_reads_nan_with_nothing_in_range():
    ctrl = controller()
    horizontal = np.eye(4)                       # flange z along world x, over the table's end
    horizontal[:3, :3] = [[0, 0, 1], [0, 1, 0], [-1, 0, 0]]
    horizontal[:3, 3] = (0.6, 0.05, 0.9)
    move_to(ctrl, joints_for(ctrl, horizontal), 0.8)
    assert np.allclose(matrix(*ctrl.world.flange_pose()), horizontal, atol=1e-5)
    assert math.isnan(ctrl.read_sensor("laser_standoff_sensor")[0])
    assert DEFAULT_CELL.sensors[1].max_range == 1.0
