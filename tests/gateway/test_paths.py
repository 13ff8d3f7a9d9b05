"""MoveThroughTo and MoveScrew as the arm does them, against the real gateway and device server:
watched cycle by cycle in the controller's recorder, or on the device's own state stream
(controller time)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from landscape.robot.kinematics import Kinematics
from landscape.sim.recorder import read_recording

from support import cell_file, start_server

from crcl_support import RawClient, RunningGateway, ToolWatch, field, pose
from test_gateway import MOVE, point


def _distance_to_polyline(point_: np.ndarray, line: np.ndarray) -> tuple[float, int]:
    """The distance from a point to a sampled path (K, 3), and the sample nearest it."""
    a, b = line[:-1], line[1:]
    ab = b - a
    t = np.clip(np.einsum("ij,ij->i", point_ - a, ab) / np.maximum(
        np.einsum("ij,ij->i", ab, ab), 1e-18), 0.0, 1.0)
    distances = np.linalg.norm(a + t[:, None] * ab - point_, axis=1)
    return float(distances.min()), int(distances.argmin())


class Recorded:
    """A device server whose controller records every cycle (its LLI recorder, as a real CS8
    does), and the gateway before it: the flange's path, cycle by cycle, of what it ran."""

    def __init__(self, directory):
        self.path = directory / "record.mcap"
        self.server = start_server(cell=cell_file(
            directory, {'path = "var/records/cs8.mcap"': f'path = "{self.path}"'}))
        self.gateway = RunningGateway(self.server.target)
        self.link = self.server.link
        self.link.between_cycles(lambda c: c.rec_init())

    def start(self) -> None:
        self.link.between_cycles(lambda c: c.rec_start())

    def flange(self) -> tuple[np.ndarray, np.ndarray]:
        """(times (K,), flange positions (K, 3) in the world: the base is at its origin)."""
        self.link.between_cycles(lambda c: (c.rec_stop(), c.rec_store()))
        data = read_recording(str(self.path))
        return data["t"], Kinematics(self.server.device.arm).forward(data["fbk_pos"])[:, :3, 3]

    def close(self) -> None:
        self.gateway.close()
        self.server.stop(grace=None)


@pytest.fixture
def recorded(tmp_path):
    running = Recorded(tmp_path)
    yield running
    running.close()


def test_move_through_to_passes_the_middle_waypoints_without_stopping(recorded):
    client = RawClient(recorded.gateway.port)
    client.run("InitCanon", 1)
    speed = 0.2                                       # m/s
    client.run("SetTransSpeed", 2, '<TransSpeed xsi:type="TransSpeedAbsoluteType"><Setting>'
                                   f"{speed}</Setting></TransSpeed>")
    tolerance = 0.001
    client.run("SetIntermediatePoseTolerance", 3, "<Tolerance>" + "".join(
        f"<{axis}PointTolerance>{tolerance}</{axis}PointTolerance>" for axis in "XYZ") +
        "</Tolerance>")
    client.run("MoveTo", 4, MOVE.format("false") + pose(0.45, 0.3, 0.6))
    middle = [(0.5, 0.2, 0.6), (0.55, 0.0, 0.55)]
    last = (0.5, -0.2, 0.6)
    recorded.start()
    done = client.run("MoveThroughTo", 5, MOVE.format("true") + "".join(
        pose(*p, tag="Waypoint") for p in (*middle, last)) + "<NumPositions>3</NumPositions>")
    client.close()
    assert field(done, "CommandState") == "CRCL_Done", done
    assert point(done) == pytest.approx(last, abs=1e-4)
    times, flange = recorded.flange()                 # no tool: the flange is the controlled point
    assert flange[-1] == pytest.approx(last, abs=1e-4)
    velocity = np.linalg.norm(np.diff(flange, axis=0), axis=1) / np.diff(times)
    for waypoint in middle:
        distance, nearest = _distance_to_polyline(np.array(waypoint), flange)
        assert distance <= tolerance, (waypoint, distance)
        # passing, not stopping there: still at a good part of the speed asked
        assert velocity[max(0, nearest - 2):nearest + 2].min() > 0.3 * speed, (
            waypoint, velocity[max(0, nearest - 2):nearest + 2])
    assert velocity.max() <= speed * 1.02


def test_move_screw_from_a_start_pose_about_an_axis_point_after_a_free_advance(server, client):
    client.run("MoveTo", 2, MOVE.format("false") + pose(0.5, 0.1, 0.6))
    start, center = np.array([0.5, 0.0, 0.6]), np.array([0.5, 0.05, 0.6])
    watch = ToolWatch(server.target, rate_hz=0)
    done = client.run("MoveScrew", 3, pose(*start, tag="StartPosition") +
                      "<AxisPoint><X>0.5</X><Y>0.05</Y><Z>0.6</Z></AxisPoint>"
                      "<AxialDistanceFree>0.01</AxialDistanceFree>"
                      "<AxialDistanceScrew>0.01</AxialDistanceScrew>"
                      f"<Turn>{math.pi / 2}</Turn>")
    assert field(done, "CommandState") == "CRCL_Done", done
    # the tool's Z points down: +0.01 free and +0.01 screw go 2 cm down; a quarter turn
    # counterclockwise seen from below (clockwise from above) about the vertical through the
    # axis point takes the tip from 5 cm in -Y of the axis to 5 cm in -X of it
    assert point(done) == pytest.approx((0.45, 0.05, 0.58), abs=1e-4)
    x_axis = [float(field(field(done, "XAxis"), t)) for t in "IJK"]
    assert x_axis == pytest.approx((0.0, -1.0, 0.0), abs=1e-4)
    times, tool = watch.moved()
    at_start = np.flatnonzero(np.linalg.norm(tool[:, :3] - start, axis=1) < 1e-4)[0]
    after = tool[at_start:]
    # from the start on, the tip keeps its 5 cm from the screw's axis (the vertical through
    # the axis point), going only down, and the turn follows the advance
    radius = np.linalg.norm(after[:, :2] - center[:2], axis=1)
    assert radius == pytest.approx(0.05, abs=5e-4)
    assert np.all(np.diff(after[:, 2]) <= 1e-6)
    turned = Rotation.from_euler("xyz", after[:, 3:])
    angle = (turned * turned[0].inv()).magnitude()
    # no turn on the free advance (down to 0.59), then a quarter turn per 0.01 m
    screwed = np.clip((0.59 - after[:, 2]) / 0.01, 0.0, 1.0)
    assert angle == pytest.approx(screwed * math.pi / 2, abs=0.02)
