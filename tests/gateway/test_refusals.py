"""A pose out of the arm's reach, out of a joint's range or into the cell is a CRCL_Error that
says so first (which waypoint, which bodies), at once and with nothing moved; the session goes
on with the next command, as CRCL allows (issue 27 item 4)."""
from __future__ import annotations

import numpy as np
import pytest

from landscape.client import Robot

from crcl_support import field, pose
from test_gateway import MOVE, point

START = (0.5, 0.0, 0.6)          # in reach, the flange pointing down
INTO_THE_TABLE = (0.6, 0.0, 0.1)  # the table's top is at z = 0.2


def _joints(server) -> np.ndarray:
    with Robot(server.target, "watcher") as robot:
        return np.array(robot.get_robot_position().joint_position)


def _refused(client, server, kind: str, command_id: int, body: str) -> str:
    before = _joints(server)
    status = client.run(kind, command_id, body)
    assert field(status, "CommandState") == "CRCL_Error", status
    assert np.abs(_joints(server) - before).max() < 1e-6          # nothing moved
    return field(status, "StateDescription")


def _waypoints(*points) -> str:
    return (MOVE.format("false") + "".join(pose(*p, tag="Waypoint") for p in points)
            + f"<NumPositions>{len(points)}</NumPositions>")


@pytest.fixture
def at_start(client):
    assert field(client.run("MoveTo", 2, MOVE.format("false") + pose(*START)),
                 "CommandState") == "CRCL_Done"
    return client


def test_out_of_reach_is_said_at_once_and_the_session_goes_on(at_start, server):
    said = _refused(at_start, server, "MoveTo", 3, MOVE.format("false") + pose(2.5, 1, 1))
    assert said.startswith("the target is out of the arm's reach, nothing moved: ")
    assert "the arm reaches 1.05 m at most" in said
    said = _refused(at_start, server, "MoveThroughTo", 4, _waypoints((0.5, 0.1, 0.6), (2.5, 1, 1)))
    assert said.startswith("waypoint 2 is out of the arm's reach, nothing moved: ")
    done = at_start.run("MoveTo", 5, MOVE.format("true") + pose(0.5, 0.1, 0.6))
    assert field(done, "CommandState") == "CRCL_Done"
    assert point(done) == pytest.approx((0.5, 0.1, 0.6), abs=1e-4)


def test_a_pose_into_the_cell_names_the_bodies_that_would_collide(at_start, server):
    for command_id, straight in ((3, "true"), (4, "false")):
        said = _refused(at_start, server, "MoveTo", command_id,
                        MOVE.format(straight) + pose(*INTO_THE_TABLE))
        assert said.startswith("the motion would collide, nothing moved: ")
        assert "link6 meets table" in said
    said = _refused(at_start, server, "MoveThroughTo", 5,
                    _waypoints((0.5, 0.1, 0.6), INTO_THE_TABLE))
    assert said.startswith("the motion would collide, nothing moved: ") and "table" in said
    assert field(at_start.run("Dwell", 6, "<DwellTime>0</DwellTime>"), "CommandState") == \
        "CRCL_Done"


def test_a_joint_beyond_its_range_is_said_so(at_start, server):
    said = _refused(at_start, server, "ActuateJoints", 3,
                    '<ActuateJoint><JointNumber>1</JointNumber><JointPosition>3.8</JointPosition>'
                    '<JointDetails xsi:type="JointSpeedAccelType"></JointDetails></ActuateJoint>')
    assert said == ("the target is out of a joint's range, nothing moved: joint 1 target 3.8 rad "
                    "is outside its range [-3.14159, 3.14159] rad")
