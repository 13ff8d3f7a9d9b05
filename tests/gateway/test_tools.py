"""The tool changer, the gripper and the vendor hook through CRCL, against the real gateway and
device server in the default cell (a rack with a gripper at (-0.1, -0.6), plate at z 0.461, and
a vacuum cup; tools hang down from their plates)."""
from __future__ import annotations

import re

import pytest

from crcl_support import field, pose
from test_gateway import MOVE, point

PLATE = (-0.1, -0.6, 0.461)      # the gripper's plate in its slot (the flange's pose to couple)
GRIPPER_LENGTH = 0.16            # plate to finger tips
AWAY = (0.5, 0.0, 0.6)


def gripper(status: str) -> str | None:
    """The GripperStatus element's content (it carries an xsi:type), or None."""
    match = re.search(r"<GripperStatus[^>]*>(.*?)</GripperStatus>", status, re.S)
    return match.group(1) if match else None


def _ok(status: str) -> str:
    assert field(status, "CommandState") == "CRCL_Done", status
    return status


def _couple_from_above(client) -> None:
    """The flange 0.1 m above the gripper's plate, on its axis; CloseToolChanger there."""
    _ok(client.run("MoveTo", 2, MOVE.format("false") + pose(PLATE[0], PLATE[1], PLATE[2] + 0.1)))
    coupled = _ok(client.run("CloseToolChanger", 3))
    assert "tool gripper coupled" in field(coupled, "StateDescription")


def test_couple_grip_and_put_back_the_gripper(client):
    assert gripper(client.status()) is None     # no tool: none reported
    _couple_from_above(client)
    status = client.status()                 # validated against CRCLStatus.xsd by the client
    held = gripper(status)
    assert held is not None and field(held, "GripperName") == "gripper", status
    assert 'xsi:type="ParallelGripperStatusType"' in status
    tip = point(status)                      # the controlled point is now the finger tips
    assert tip[:2] == pytest.approx(PLATE[:2], abs=1e-3)
    assert tip[2] < PLATE[2] + 0.3 - GRIPPER_LENGTH + 1e-3

    _ok(client.run("SetEndEffector", 4, "<Setting>0</Setting>"))     # closed
    assert float(field(gripper(client.status()), "Separation")) == 0.0
    _ok(client.run("SetEndEffector", 5, "<Setting>1</Setting>"))     # open
    assert float(field(gripper(client.status()), "Separation")) == \
        pytest.approx(0.08)

    # away from the rack the changer stays closed: the tool would drop
    _ok(client.run("MoveTo", 6, MOVE.format("false") + pose(*AWAY)))
    refused = client.run("OpenToolChanger", 7)
    assert field(refused, "CommandState") == "CRCL_Error", refused
    assert "not at its rack slot" in field(refused, "StateDescription")
    assert gripper(client.status()) is not None

    # back above the slot (where the tool came out): the device puts it back
    _ok(client.run("MoveTo", 8, MOVE.format("false") + pose(*tip)))
    released = _ok(client.run("OpenToolChanger", 9))
    assert "released into its slot" in field(released, "StateDescription")
    assert gripper(client.status()) is None


def test_close_tool_changer_away_from_the_rack_is_an_error(client):
    _ok(client.run("MoveTo", 2, MOVE.format("false") + pose(*AWAY)))
    refused = client.run("CloseToolChanger", 3)
    assert field(refused, "CommandState") == "CRCL_Error", refused
    assert "at no tool changer" in field(refused, "StateDescription")
    assert gripper(client.status()) is None


def test_set_end_effector_with_no_tool_is_an_error(client):
    refused = client.run("SetEndEffector", 2, "<Setting>1</Setting>")
    assert field(refused, "CommandState") == "CRCL_Error", refused
    assert "no end effector" in field(refused, "StateDescription")


def test_couple_with_the_flange_moved_into_the_slot(client):
    """A CRCL client moves the flange onto the plate itself (the device allows the bare flange
    to dock along the coupling's axis), then closes the changer."""
    _ok(client.run("MoveTo", 2, MOVE.format("false") + pose(PLATE[0], PLATE[1], PLATE[2] + 0.1)))
    _ok(client.run("MoveTo", 3, MOVE.format("true") + pose(*PLATE)))
    coupled = _ok(client.run("CloseToolChanger", 4))
    assert "tool gripper coupled" in field(coupled, "StateDescription")
    assert field(gripper(client.status()), "GripperName") == "gripper"
    released = _ok(client.run("OpenToolChanger", 5))
    assert "tool gripper released" in field(released, "StateDescription")


def test_run_program_hands_text_to_the_vendor_hook_and_refuses_unknown_programs(client):
    ran = _ok(client.run("RunProgram", 2, "<ProgramText>version</ProgramText>"))
    assert "vendor program ran: landscape-grpc" in field(ran, "StateDescription")
    unknown = client.run("RunProgram", 3, "<ProgramText>weld seam 7</ProgramText>")
    assert field(unknown, "CommandState") == "CRCL_Error", unknown
    assert "unknown vendor command 'weld seam 7'" in field(unknown, "StateDescription")
