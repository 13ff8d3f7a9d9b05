"""Issue 10, seed 3.8.1: tools fetched from and returned to the rack, pick and place with the
gripper and with the vacuum cup, on the real server with the simulated cell (lock-step clock).
The parts move because the simulation holds them, never because a test moved them."""
from __future__ import annotations

import grpc
import numpy as np
import pytest

from landscape.server.device.states import State
from landscape.v1 import digital_io_service_pb2 as io_pb
from landscape.v1 import end_effector_pb2 as ee
from landscape.v1 import control_pb2, motion_pb2, sensing_pb2, types_pb2

from support import Arm, error_info, stubs, wait_until

# Weights, contacts and readings of the world: the pybullet backend's (tests/conftest.py).
pytestmark = pytest.mark.physics

TABLE_TOP = 0.2
PLACE_X = 0.73                      # the place zone's centre line
PICK_BIT, PLACE_BIT = 1 << 3, 1 << 4   # part_at_pick, part_at_place (unit 1)


@pytest.fixture
def arm(tmp_path):
    a = Arm(tmp_path)
    yield a
    a.close()


def _state(arm) -> tuple[str, str]:
    reply = arm.device.GetEndEffectorState(ee.GetEndEffectorStateRequest())
    return reply.current_ee, reply.ee_state


def _inputs(arm) -> int:
    _, io, _ = stubs(arm.session.channel)
    return io.GetDigitalIO(io_pb.GetDigitalIORequest(type="input", unit_id=1)).bits_on


def _world(arm, func):
    return arm.link.between_cycles(func)


def _part(arm, name: str) -> np.ndarray:
    return np.array(_world(arm, lambda c: c.world.part_pose(name)[0]))


def _only_part(arm, keep: str) -> None:
    """Take the other parts out of the cell, as a person would, so the zone inputs see one."""
    for name in ("block_1", "block_2", "plate_1"):
        if name != keep:
            _world(arm, lambda c, n=name: c.panel.remove_part(n))


def _attached(arm) -> dict[str, str]:
    """What the device's cell description says moves with the arm."""
    cell = arm.device.GetCellDescription(control_pb2.GetCellDescriptionRequest())
    return {body.name: body.attached_to for body in cell.bodies if body.attached_to}


def _lift(arm, dz: float) -> None:
    reply = arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
        frame=types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME, values=[0, 0, dz, 0, 0, 0],
        motion_type=types_pb2.MOTION_TYPE_STRAIGHT_MOTION), timeout=30)
    assert arm.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"


def _touch_down(arm) -> None:
    """MoveReact down until the tool, or what it holds, presses 5 N on what is below."""
    reply = arm.device.MoveReact(sensing_pb2.MoveReactRequest(
        sensor_type="force_sensor", motion=types_pb2.Vector3(z=0.05), speed=0.5,
        thresholds=types_pb2.Vector3(z=-5)), timeout=30)
    events = arm.wait_command(reply.ret_val.command_id)
    assert events[-1].command.message.startswith("triggered"), events[-1]


def _pick_and_place(arm, tool: str, part: str, grip_height: float, held_state: str) -> None:
    """Over the part, down, take it, lift, over the place zone, down, let go, lift; the part
    must lie within 5 mm of the place point and the zone inputs follow it. A gripper goes down
    around its part by a plain move (with room on every side); a cup searches down for its
    part, and the part held searches down for the table (MoveReact), both meant to touch."""
    start = _part(arm, part)
    assert _inputs(arm) & (PICK_BIT | PLACE_BIT) == PICK_BIT
    if tool == "gripper":
        arm.move_down_to(start[0], start[1], start[2] + grip_height + 0.1)
        _lift(arm, -0.1)
    else:
        arm.move_down_to(start[0], start[1], start[2] + grip_height + 0.02)
        _touch_down(arm)
    reply = arm.device.ActivateTool(ee.ActivateToolRequest(tool_id=tool, bit_field=1))
    assert _state(arm) == (tool, held_state), reply.ret_val.ret_msg
    _lift(arm, 0.1)
    lifted = _part(arm, part)
    assert lifted == pytest.approx(start + [0, 0, 0.1], abs=2e-3)   # it came along
    assert _attached(arm) == {tool: "flange", part: "tool"}          # as the device knows it
    assert _inputs(arm) & (PICK_BIT | PLACE_BIT) == 0               # out of the pick zone

    arm.move_down_to(PLACE_X, start[1], start[2] + grip_height + 0.02)
    _touch_down(arm)
    assert _inputs(arm) & PLACE_BIT
    arm.device.DeactivateTool(ee.DeactivateToolRequest(tool_id=tool, bit_field=1))
    assert _state(arm)[1] in ("open", "off")
    _lift(arm, 0.1)
    placed = _part(arm, part)
    assert _attached(arm) == {tool: "flange"}
    print(f"\n{part} placed with the {tool} at {np.round(placed, 4)}")
    assert np.linalg.norm(placed - [PLACE_X, start[1], start[2]]) < 0.005
    assert _inputs(arm) & (PICK_BIT | PLACE_BIT) == PLACE_BIT


def test_get_and_put_tool_change_the_tool_and_its_offset(arm):
    assert _state(arm) == ("", "none")
    slot = _world(arm, lambda c: c.world.tools["gripper"].plate_pose())
    arm.get_tool("gripper")
    assert _state(arm) == ("gripper", "open")
    offset = arm.server.device.settings.tool_offset
    assert offset[:3, 3] == pytest.approx([0, 0, 0.16])
    steps = [e.detail.point_name for e in arm.history()
             if e.event_id == "command_done" and e.detail.command == "GetTool"]
    assert steps == ["gripper: approach", "gripper: into the slot", "gripper: out of the rack"]
    assert arm.tool_tip()[2, 3] > 0.3 + 0.05                   # tip clear above the rack

    error = _refused(lambda: arm.get_tool("vacuum"))
    assert error.code() is grpc.StatusCode.FAILED_PRECONDITION and "PutTool" in error.details()

    arm.device.PutTool(ee.PutToolRequest(tool_id="gripper"), timeout=120)
    assert _state(arm) == ("", "none")
    assert np.allclose(arm.server.device.settings.tool_offset, np.eye(4))
    back = _world(arm, lambda c: (c.world.mounted, c.world.tools["gripper"].plate_pose()))
    assert back[0] is None
    assert np.allclose(back[1][0], slot[0], atol=1e-3)         # docked in its slot
    assert arm.server.device.state is State.RESTING


def test_pick_and_place_with_the_gripper(arm):
    _only_part(arm, "block_2")
    arm.get_tool("gripper")
    _pick_and_place(arm, "gripper", "block_2", grip_height=0.0, held_state="closed")
    arm.device.PutTool(ee.PutToolRequest(tool_id="gripper"), timeout=120)
    assert _state(arm) == ("", "none")


def test_pick_and_place_with_the_vacuum_cup(arm):
    _only_part(arm, "plate_1")
    arm.get_tool("vacuum")
    arm.device.ActivateTool(ee.ActivateToolRequest(tool_id="vacuum", bit_field=1))
    assert _state(arm) == ("vacuum", "suction_on")              # on, nothing held yet
    arm.device.DeactivateTool(ee.DeactivateToolRequest(tool_id="vacuum", bit_field=1))
    _pick_and_place(arm, "vacuum", "plate_1", grip_height=0.005, held_state="holding")
    arm.device.PutTool(ee.PutToolRequest(tool_id="vacuum"), timeout=120)
    assert _state(arm) == ("", "none")


def _refused(call) -> grpc.RpcError:
    with pytest.raises(grpc.RpcError) as refused:
        call()
    return refused.value


def test_tool_commands_refuse_what_does_not_fit_and_change_nothing(arm):
    before = arm.joints().copy()
    cases = [
        (lambda: arm.get_tool("wrench"), grpc.StatusCode.INVALID_ARGUMENT),
        (lambda: arm.device.PutTool(ee.PutToolRequest(tool_id="gripper")),
         grpc.StatusCode.FAILED_PRECONDITION),                        # nothing on the flange
        (lambda: arm.device.ActivateTool(ee.ActivateToolRequest(tool_id="gripper", bit_field=1)),
         grpc.StatusCode.FAILED_PRECONDITION),
    ]
    for call, code in cases:
        error = _refused(call)
        assert error.code() is code, error.details()
    assert np.allclose(arm.joints(), before, atol=1e-6)
    arm.get_tool("vacuum")
    error = _refused(lambda: arm.device.ActivateTool(
        ee.ActivateToolRequest(tool_id="vacuum", bit_field=2)))
    assert error.code() is grpc.StatusCode.OUT_OF_RANGE
    assert error_info(error).metadata["ret_code"] == "-3"
    assert _state(arm) == ("vacuum", "off")


def _grip_block_2(arm) -> np.ndarray:
    """block_2 alone on the table, in the gripper (closed around it where it lay); where it
    lay."""
    _only_part(arm, "block_2")
    arm.get_tool("gripper")
    start = _part(arm, "block_2")
    arm.move_down_to(start[0], start[1], start[2] + 0.1)
    _lift(arm, -0.1)
    arm.device.ActivateTool(ee.ActivateToolRequest(tool_id="gripper", bit_field=1))
    return start


def test_a_held_part_carried_into_the_table_is_refused_and_free_space_is_not(arm):
    """Issue 11: the part in the gripper is part of the arm for the collision check."""
    start = _grip_block_2(arm)
    _lift(arm, 0.1)
    before = arm.joints().copy()
    # Straight down by as much as it was lifted: the block (hanging 2 cm below the finger
    # tips) would meet the table top while the fingers stay 2 cm above it.
    refused = _refused(lambda: arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
        frame=types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME, values=[0, 0, -0.1, 0, 0, 0],
        motion_type=types_pb2.MOTION_TYPE_STRAIGHT_MOTION), timeout=30))
    info = error_info(refused)
    assert refused.code() == grpc.StatusCode.FAILED_PRECONDITION and info.reason == "COLLISION"
    assert {info.metadata["body_a"], info.metadata["body_b"]} == {"block_2", "table"}
    assert "block_2" in refused.details() and "table" in refused.details()
    assert np.allclose(arm.joints(), before, atol=1e-6)         # nothing moved
    assert arm.server.device.state is State.RESTING

    reply = arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(   # free space: it runs
        frame=types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME, values=[0, 0.1, 0.05, 0, 0, 0],
        motion_type=types_pb2.MOTION_TYPE_STRAIGHT_MOTION), timeout=30)
    assert arm.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"
    assert _part(arm, "block_2") == pytest.approx(start + [0, 0.1, 0.15], abs=3e-3)


# ---- the collision scene follows the parts (issue 11) -----------------------------------------

def _scene_part(arm, name: str) -> np.ndarray:
    return arm.server.device.collisions.part_pose(name)[:3, 3]


def _by_hand(arm, part: str, change) -> None:
    """A person moves `part` (the panel); the device's scene follows within its period."""
    _world(arm, change)
    wait_until(lambda: np.allclose(_scene_part(arm, part), _part(arm, part), atol=1e-3))


def test_a_part_a_person_puts_in_the_way_is_an_obstacle_and_one_taken_away_is_not(arm):
    arm.move_down_to(0.65, 0.3, 0.45)
    before = arm.joints().copy()
    down = motion_pb2.MoveAbsoluteRequest(
        frame=types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME,
        values=[0.65, 0.3, TABLE_TOP + 0.035, np.pi, 0, 0],
        motion_type=types_pb2.MOTION_TYPE_STRAIGHT_MOTION)
    _by_hand(arm, "block_1",
             lambda c: c.panel.place_part("block_1", (0.65, 0.3, TABLE_TOP + 0.0201)))
    refused = _refused(lambda: arm.device.MoveAbsolute(down, timeout=30))
    info = error_info(refused)
    assert refused.code() is grpc.StatusCode.FAILED_PRECONDITION and info.reason == "COLLISION"
    assert info.metadata["body_b"] == "block_1"
    assert np.allclose(arm.joints(), before, atol=1e-6)
    _by_hand(arm, "block_1", lambda c: c.panel.remove_part("block_1"))
    reply = arm.device.MoveAbsolute(down, timeout=30)
    assert arm.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"


def test_a_part_let_go_above_the_table_lies_on_the_table_in_the_scene(arm):
    start = _grip_block_2(arm)
    _lift(arm, 0.08)
    arm.device.DeactivateTool(ee.DeactivateToolRequest(tool_id="gripper", bit_field=1))
    landed = _part(arm, "block_2")
    assert landed[2] == pytest.approx(start[2], abs=2e-3)          # it fell onto the table
    assert _scene_part(arm, "block_2") == pytest.approx(landed, abs=1e-3)
    assert _attached(arm) == {"gripper": "flange"}


def test_a_tool_change_is_checked_whole_before_the_arm_moves(arm):
    """A block left on the gripper's plate: the way into the slot is blocked, so GetTool is
    refused before its approach runs (step by step, the arm went there first)."""
    plate = _world(arm, lambda c: c.world.tools["gripper"].plate_pose())[0]
    _by_hand(arm, "block_1",
             lambda c: c.panel.place_part("block_1", np.add(plate, (0, 0, 0.0215))))
    before = arm.joints().copy()
    refused = _refused(lambda: arm.get_tool("gripper"))
    info = error_info(refused)
    assert refused.code() is grpc.StatusCode.FAILED_PRECONDITION and info.reason == "COLLISION"
    assert info.metadata["body_b"] == "block_1" and "into the slot" in refused.details()
    assert np.allclose(arm.joints(), before, atol=1e-6)              # nothing moved
    assert not [e for e in arm.history() if e.event_id == "command_started"
                and e.detail.command == "GetTool"]
    _by_hand(arm, "block_1", lambda c: c.panel.remove_part("block_1"))
    arm.get_tool("gripper")
    assert _state(arm) == ("gripper", "open")
