"""The cell's workstation (issue 27 items 1, 2): CRCL's frame where the cell says, the units a
program starts in, the end effector the arm holds from InitCanon on; and what one CRCL session
sets (its frame, units, speeds, a tool offset) stays its own: nothing of it is left on the
device when it ends, and no other client sees it meanwhile."""
from __future__ import annotations

import math
import time

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from landscape.client import Robot
from landscape.gateway.__main__ import arguments, workstation
from landscape.gateway.workstation import BARE, Workstation

from crcl_support import RawClient, RunningGateway, field, pose
from test_gateway import MOVE, point

# CRCL's frame 0.2 m forward, 0.1 m to the right and 0.15 m up from the base, turned a
# quarter turn about z: CRCL's X is the base's y.
FRAME = (0.2, -0.1, 0.15, 0.0, 0.0, math.pi / 2)
BASE_GOAL = np.array([0.5, 0.1, 0.6])     # in reach, the flange pointing down


def _matrix(values) -> np.ndarray:
    out = np.eye(4)
    out[:3, :3] = Rotation.from_euler("xyz", values[3:]).as_matrix()
    out[:3, 3] = values[:3]
    return out


def _in_frame(point_base: np.ndarray, frame) -> np.ndarray:
    inverse = np.linalg.inv(_matrix(frame))
    return inverse[:3, :3] @ point_base + inverse[:3, 3]


def _base_position(server) -> np.ndarray:
    """Where the device says the tool tip is, in its base frame (its world frame is the base
    unless a client set it; the tests check it is)."""
    with Robot(server.target, "watcher") as robot:
        p = robot.get_robot_position().world_position
    return np.array([p.x, p.y, p.z])


@pytest.fixture
def cell(server, request):
    """The gateway of a cell whose workstation the test names (indirect parameter)."""
    running = RunningGateway(server.target, workstation=request.param)
    client = RawClient(running.port)
    yield running, client
    client.close()
    running.close()


def _ok(status: str) -> str:
    assert field(status, "CommandState") == "CRCL_Done", status
    return status


@pytest.mark.parametrize("cell", [Workstation(FRAME)], indirect=True)
def test_poses_are_in_the_cells_workstation_frame_and_the_device_keeps_its_own(cell, server):
    _, client = cell
    _ok(client.run("InitCanon", 1))
    goal = _in_frame(BASE_GOAL, FRAME)
    # the tool pointing down: -z of the base, whatever the frame's turn about z
    x_axis = _matrix(FRAME)[:3, :3].T @ np.array([1.0, 0.0, 0.0])
    done = _ok(client.run("MoveTo", 2, MOVE.format("true") + pose(
        *goal, xaxis=tuple(x_axis), zaxis=(0, 0, -1))))
    assert point(done) == pytest.approx(tuple(goal), abs=1e-4)
    assert _base_position(server) == pytest.approx(BASE_GOAL, abs=1e-4)
    assert np.array_equal(server.device.settings.world_frame, np.eye(4))


@pytest.mark.parametrize("cell", [Workstation(length_unit="millimeter", angle_unit="degree")],
                         indirect=True)
def test_a_program_starts_in_the_cells_units(cell):
    _, client = cell
    _ok(client.run("InitCanon", 1))
    done = _ok(client.run("MoveTo", 2, MOVE.format("false") + pose(*(BASE_GOAL * 1000))))
    assert point(done) == pytest.approx(tuple(BASE_GOAL * 1000), abs=0.1)
    joints = _ok(client.run("ActuateJoints", 3, '<ActuateJoint><JointNumber>6</JointNumber>'
                            '<JointPosition>30</JointPosition><JointDetails xsi:type='
                            '"JointSpeedAccelType"></JointDetails></ActuateJoint>'))
    assert "joints reached" in field(joints, "StateDescription")
    six = [j for j in client.status().split("<JointStatus>") if "<JointNumber>6<" in j][0]
    assert float(field(six, "JointPosition")) == pytest.approx(30.0, abs=0.05)


def test_a_sessions_workstation_frame_is_its_own(gateway, server):
    """SetRobotParameters WorkstationFrame holds for the session that sent it: the device's
    world frame never changes, and the next session is in the cell's frame again."""
    client = RawClient(gateway.port)
    try:
        _ok(client.run("InitCanon", 1))
        _ok(client.run("SetRobotParameters", 2, "<ParameterSetting><ParameterName>"
                       "WorkstationFrame</ParameterName><ParameterValue>0.1 0 0 0 0 0"
                       "</ParameterValue></ParameterSetting>"))
        done = _ok(client.run("MoveTo", 3, MOVE.format("true") + pose(*(BASE_GOAL - [0.1, 0, 0]))))
        assert point(done) == pytest.approx(tuple(BASE_GOAL - [0.1, 0, 0]), abs=1e-4)
        assert _base_position(server) == pytest.approx(BASE_GOAL, abs=1e-4)
        assert np.array_equal(server.device.settings.world_frame, np.eye(4))
        _ok(client.run("EndCanon", 4))
        _ok(client.run("InitCanon", 5))
        assert point(client.status()) == pytest.approx(tuple(BASE_GOAL), abs=1e-4)
    finally:
        client.close()


def _device_settings(server) -> tuple:
    with Robot(server.target, "watcher") as robot:
        units = robot.get_units()
        speeds, accels = robot.get_velocities(), robot.get_accelerations()
        offset = robot.get_tool_offsets().offset
    return ((units.linear_units, units.angular_units),
            (speeds.percent_velocity, speeds.world_linear_velocity, speeds.world_angular_velocity),
            (accels.percent_accel, accels.world_linear_accel, accels.world_angular_accel),
            (offset.x, offset.y, offset.z, offset.roll, offset.pitch, offset.yaw))


@pytest.mark.parametrize("ending", ["EndCanon", "disconnect"])
def test_what_a_session_set_on_the_device_is_put_back_when_it_ends(gateway, server, ending):
    from landscape.client import AngularUnit, LinearUnit, SpeedType
    with Robot(server.target, "another program") as robot, robot.control(activate=False):
        robot.set_units(LinearUnit.MILLIMETERS, AngularUnit.DEGREES)
        robot.set_speed(37.0)
        robot.set_speed(900.0, SpeedType.LINEAR)        # mm/s
    before = _device_settings(server)
    client = RawClient(gateway.port)
    try:
        _ok(client.run("InitCanon", 1))
        _ok(client.run("SetTransSpeed", 2, '<TransSpeed xsi:type="TransSpeedAbsoluteType">'
                                           "<Setting>0.3</Setting></TransSpeed>"))
        _ok(client.run("SetRotSpeed", 3, '<RotSpeed xsi:type="RotSpeedAbsoluteType">'
                                         "<Setting>0.5</Setting></RotSpeed>"))
        _ok(client.run("MoveTo", 4, MOVE.format("true") + pose(*BASE_GOAL)))
        _ok(client.run("SetRobotParameters", 5, "<ParameterSetting><ParameterName>ToolOffset"
                       "</ParameterName><ParameterValue>0 0 0.05 0 0 0</ParameterValue>"
                       "</ParameterSetting>"))
        assert _device_settings(server) != before          # the session's, while it runs
        if ending == "EndCanon":
            _ok(client.run("EndCanon", 6))
    finally:
        client.close()
    _until_unlocked(server)
    assert _device_settings(server) == before


def _until_unlocked(server, timeout: float = 20.0) -> None:
    """Until the device's lock is free (a closed connection ends its session in its time)."""
    with Robot(server.target, "watcher") as robot:
        deadline = time.monotonic() + timeout
        while robot.get_device_state().locked:
            assert time.monotonic() < deadline, "the gateway's session kept the lock"
            time.sleep(0.02)


@pytest.mark.parametrize("cell", [Workstation(end_effector="gripper")], indirect=True)
def test_init_canon_fetches_the_cells_end_effector_and_comes_back(cell, server):
    _, client = cell
    with Robot(server.target, "watcher") as robot:
        stood = np.array(robot.get_robot_position().joint_position)
        started = _ok(client.run("InitCanon", 1, timeout=120))
        assert "the gripper fetched from the rack" in field(started, "StateDescription")
        assert robot.get_end_effector_state().current_ee == "gripper"
        assert np.array(robot.get_robot_position().joint_position) == pytest.approx(stood,
                                                                                abs=1e-3)
    assert "<GripperName>gripper</GripperName>" in client.status()
    _ok(client.run("EndCanon", 2))
    again = _ok(client.run("InitCanon", 3))          # on the flange already: nothing to do
    assert "fetched" not in field(again, "StateDescription")


@pytest.mark.parametrize("cell", [Workstation(end_effector="spanner")], indirect=True)
def test_an_end_effector_the_cell_cannot_give_is_refused_and_the_lock_freed(cell, server):
    _, client = cell
    refused = client.run("InitCanon", 1)
    assert field(refused, "CommandState") == "CRCL_Error"
    assert ("the cell's end effector 'spanner' is no tool of this cell's rack (gripper, vacuum)"
            in field(refused, "StateDescription"))
    with Robot(server.target, "watcher") as robot:
        assert not robot.get_device_state().locked


def test_the_command_line_names_the_workstation():
    args = arguments(["--workstation-frame", "0.2, -0.1, 0.15, 0, 0, 1.5708",
                      "--end-effector", BARE, "--length-units", "millimeter"])
    assert workstation(args) == Workstation((0.2, -0.1, 0.15, 0.0, 0.0, 1.5708), BARE,
                                            "millimeter", "radian")
    with pytest.raises(SystemExit):
        arguments(["--workstation-frame", "0.2 0.1"])
    with pytest.raises(SystemExit):
        arguments(["--angle-units", "gradian"])
