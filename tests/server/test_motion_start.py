"""Issue 31 item 4: motion that starts in a cycle. On the lock-step clock, read on the feedback
ring (one row per cycle): the cycle that takes a run from the server already moves the arm."""
from __future__ import annotations

import numpy as np
import pytest

from landscape.server.cycle.feedback import CMD, WALL
from landscape.v1 import motion_pb2, types_pb2

from support import Arm, wait_until

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
HOME = [0.0, 0.3, 1.4, 0.0, 0.9, 0.0]


@pytest.fixture
def fast(tmp_path):
    """The kinematic backend: the arm follows its setpoints exactly, fast."""
    a = Arm(tmp_path, backend="kinematic")
    yield a
    a.close()


def started_cycles(arm) -> list[float]:
    """The tick stamps of the cycles that took a run (the executor's "started" reports)."""
    stamps: list[float] = []
    device = arm.server.device
    original = device.on_cycle_message

    def spy(msg):
        if isinstance(msg, dict) and msg.get("op") == "started":
            stamps.append(msg["wall_time"])
        original(msg)
    device.on_cycle_message = spy
    return stamps


def setpoint_step(arm, wall_time: float) -> float:
    """How far the setpoint moved on the cycle stamped `wall_time` (rad, the largest joint)."""
    ring = arm.server.link.feedback
    wait_until(lambda: ring.row(ring.head)[WALL] > wall_time)
    seq = ring.head
    while ring.row(seq)[WALL] > wall_time:
        seq -= 1
    assert ring.row(seq)[WALL] == wall_time
    return float(np.max(np.abs(ring.row(seq)[CMD] - ring.row(seq - 1)[CMD])))


def run(arm, call) -> None:
    reply = call()
    assert arm.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"


def test_a_joint_move_and_a_path_from_its_first_point_move_on_the_cycle_that_takes_them(fast):
    points = [[0.3 * np.sin(i / 5), 0.3 + 0.1 * np.sin(i / 7), 1.4, 0.0, 0.9, 0.0]
              for i in range(12)]
    header = motion_pb2.PathHeader(path_name="ring", frame=JOINT,
                                   motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                   offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)
    fast.device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header, tags=[
        types_pb2.TagStruct(joint_values=q, transition_speed=40) for q in points])]),
        timeout=30)
    run(fast, lambda: fast.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        frame=JOINT, values=points[0]), timeout=30))
    stamps = started_cycles(fast)
    run(fast, lambda: fast.device.PathMove(motion_pb2.PathMoveRequest(path_name="ring"),
                                           timeout=30))
    run(fast, lambda: fast.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        frame=JOINT, values=HOME), timeout=30))
    assert len(stamps) == 2
    path_step, move_step = (setpoint_step(fast, stamp) for stamp in stamps)
    assert path_step > 0.0, "the path's first cycle held the arm where it was"
    assert move_step > 0.0, "the move's first cycle held the arm where it was"
