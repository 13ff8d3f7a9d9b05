"""A blended path point is passed at its transition speed (percent of the maximum), through
gRPC on the simulated arm (lock-step clock), measured on the recorder's commanded joints."""
from __future__ import annotations

import math

import numpy as np
import pytest

from landscape.v1 import motion_pb2, settings_pb2, types_pb2

from support import Arm

JOINT, BASE = types_pb2.REFERENCE_FRAME_JOINT_FRAME, types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME
DT = 0.004


@pytest.fixture
def arm(tmp_path, backend):
    a = Arm(tmp_path, backend=backend)
    a.device.SetSpeed(settings_pb2.SetSpeedRequest(
        speed=100, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED))
    a.device.SetAcceleration(settings_pb2.SetAccelerationRequest(
        accel=100, attribute=types_pb2.ACCEL_TYPE_PERCENT_ACCEL))
    yield a
    a.close()


def run_path(arm, name, frame, motion, tags) -> dict:
    """Loads and runs a path with the recorder on; the recording."""
    head = motion_pb2.PathHeader(path_name=name, frame=frame, motion_type=motion,
                                 offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA,
                                 number_of_points=len(tags))
    arm.device.PathLoad(iter([motion_pb2.PathLoadRequest(header=head, tags=tags)]), timeout=30)
    arm.record_start()
    reply = arm.device.PathMove(motion_pb2.PathMoveRequest(path_name=name))
    events = arm.wait_command(reply.ret_val.command_id)
    assert events[-1].event_id == "command_done"
    assert [e.command.tag_name for e in events if e.event_id == "tag_reached"] == [
        t.tag_name for t in tags]
    return arm.recorded_tips()[1]


@pytest.mark.parametrize("percent", [5, 20, 40])
def test_a_joint_path_passes_its_blended_tag_at_the_transition_speed(arm, percent):
    """Issue 9 item 2: 5 % and 40 % ran alike, the tag passed at 20-34 %. The speed is the
    fastest joint's against its maximum velocity."""
    q0 = np.array([-1.0, 0.0, 1.5, 0.0, 1.0, 0.0])
    points = [q0, q0 + [1.0, 0.3, -0.2, 0.4, 0.2, 0.5], q0 + [2.0, 0.2, 0.1, 0.8, 0.5, 1.0]]
    tags = [types_pb2.TagStruct(joint_values=p, tag_name=f"p{i}",
                                transition_speed=percent if i == 1 else 0)
            for i, p in enumerate(points)]
    data = run_path(arm, f"joints{percent}", JOINT, types_pb2.MOTION_TYPE_JOINT_MOTION, tags)
    k = int(np.argmin(np.linalg.norm(data["cmd_pos"] - points[1], axis=1)))
    maximum = np.array(arm.server.device.arm.max_velocity)
    speed = 100 * np.max(np.abs(data["cmd_vel"][k]) / maximum)
    print(f"transition {percent} %: passed at {speed:.3f} % of the maximum")
    assert speed == pytest.approx(percent, rel=0.05)


@pytest.mark.parametrize("percent", [5, 10])
def test_a_straight_path_passes_its_blended_tag_at_the_transition_speed(arm, percent):
    """The tool tip's linear speed against the arm's maximum linear speed."""
    p0 = arm.tip()[:3, 3]
    corners = [p0, p0 + [0.0, 0.25, 0.0], p0 + [0.05, 0.5, -0.05]]
    tags = [types_pb2.TagStruct(x=c[0], y=c[1], z=c[2], roll=math.pi, yaw=math.pi,
                                tag_name=f"c{i}", transition_speed=percent if i == 1 else 0)
            for i, c in enumerate(corners)]
    data = run_path(arm, f"line{percent}", BASE, types_pb2.MOTION_TYPE_STRAIGHT_MOTION, tags)
    tips = arm.kin.forward(data["cmd_pos"])[:, :3, 3]
    k = int(np.argmin(np.linalg.norm(tips - corners[1], axis=1)))
    speed = np.linalg.norm(tips[k + 1] - tips[k - 1]) / (2 * DT)
    percent_of_max = 100 * speed / arm.server.device.arm.max_linear_velocity
    print(f"transition {percent} %: passed at {percent_of_max:.3f} %")
    assert percent_of_max == pytest.approx(percent, rel=0.05)
