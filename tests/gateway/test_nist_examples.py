"""NIST's example programs and commands (../shared/crcl/examples) on the cell of the worked
example, examples/06_crcl_workstation.toml (NIST's workstation on this cell's table, the gripper
held from InitCanon on), as a CRCL client written from the specification sends them: each
command in its own CRCLCommandInstance, then GetStatus until it is Done or Error, in the four
framings a client may use; every status checked against the installed schemas (issue 27).

Where a program ends, and why this cell truly cannot go on there:
- programExample.xml (41 commands) was written for a workstation some 9 m long (its poses run
  from X 1.5 to 8.75 m) and approaches every spot from 1 m above it. Its commands 1-7 run; its
  command 8 starts with (1.5, 1, 1): the gripper's tip 1 m above the table top, where a TX90
  holding it pointing down cannot go (it reaches some 0.55 m above this table before its wrist
  meets its forearm; the device says how far the flange is from the shoulder, against the
  arm's 1.05 m). No placement of the frame helps: the first spot's approach is a vertical
  metre, and the next spot (X 4 m) is 2.5 m from the first.
- programAll.xml (32 commands, one of each kind, values for the schema's sake) asks at its
  command 2 for joint 1 at 3.8 rad (beyond its +-180 degrees) and joint 3 driven by a torque
  (landscape.v1 has no call for that): ActuateJoints is refused before anything moves. Run on
  past its errors (as a CRCL client may), every other command gets its own answer:
  test_program_all_answers_every_command_on_its_own.
"""
from __future__ import annotations

import copy
import re
import socket
import time

import pytest
from lxml import etree

from landscape.cell.config import load_config
from landscape.gateway.workstation import Workstation

from crcl_support import (EXAMPLES, RawClient, RunningGateway, command, field, needs_examples,
                          needs_xsd)
from support import ROOT

XSI = "http://www.w3.org/2001/XMLSchema-instance"
FRAMINGS = ("one write per document", "byte by byte", "command and GetStatus coalesced",
            "whitespace between documents")
SPACE = b"\r\n \t\n"
# s between GetStatus polls while a command runs: polled flat out, this process's parsing and
# schema checks of the statuses took the interpreter from the lock-step device's cycles
POLL_PERIOD = 0.01

# program -> (CommandID it ends at, the start of the CRCL_Error's description); every command
# before it is Done
ENDS = {
    "programExample.xml": (8, "waypoint 1 is out of the arm's reach, nothing moved: "),
    "programExampleWithNames.xml": (8, "waypoint 1 is out of the arm's reach, nothing moved: "),
    "programAll.xml": (2, "JointForceTorque on joint 3: landscape.v1 has no call that commands "
                          "a joint's force or torque"),
    "programAllWithNames.xml": (2, "JointForceTorque on joint 3: landscape.v1 has no call that "
                                   "commands a joint's force or torque"),
}

# programAll.xml run past its errors: CommandID -> the start of the description of each
# CRCL_Error (every other command is Done)
PROGRAM_ALL_ERRORS = {
    2: "JointForceTorque on joint 3",                  # and joint 1 beyond its range
    3: "the gripper is coupled already",               # CloseToolChanger: it holds the gripper
    8: "the screw needs 4429 path points",             # 6.1 m along an axis 7 m away: far
                                                       # more than any screw a TX90 can make
    9: "waypoint 1 is out of the arm's reach",         # (8.25, 1, 1): 7 m from the table
    12: "the target is out of the arm's reach",        # (8.25, 1, 0.5)
    13: "the gripper is not at its rack slot",         # OpenToolChanger over the table
    14: "SendCommand refused by the device",           # RunProgram "GH$%kkk457 xxx  65"
    16: "the end effector gripper has no parameters",  # rhabdaciousness, fluoxity
    23: "unknown robot parameter 'empathy'",
}

# NIST's command instances, sent in one session in file order (InitCanon again after EndCanon):
# file -> the start of the CRCL_Error's description, or None for Done
COMMANDS = {
    "commandActuateJoints.xml": "JointForceTorque on joint 1",
    "commandMoveThroughTo.xml": "RotSpeed / RotAccel in a pose hold straight motions only",
    "commandMoveThroughToWithNames.xml": "waypoint 1 is out of the arm's reach",   # (2.5, 1, 1)
    "commandMoveTo.xml": "the target is out of the arm's reach",                   # (2.5, 1, 1)
    "commandSetRobotParameters.xml": "unknown robot parameter 'foo'",
}


def workstation() -> Workstation:
    """The worked example's, read from its cell file as the launcher reads it."""
    gateway = load_config(ROOT / "examples" / "06_crcl_workstation.toml").gateway
    return Workstation(gateway.workstation_frame, gateway.end_effector, gateway.length_units,
                       gateway.angle_units)


@pytest.fixture
def cell(server):
    running = RunningGateway(server.target, workstation=workstation())
    yield running
    running.close()


def instances(path) -> list[tuple[str, int, bytes]]:
    """(kind, CommandID, CRCLCommandInstance document) of each command of a program."""
    out = []
    for element in etree.parse(str(path)).getroot():
        if element.tag not in ("InitCanon", "MiddleCommand", "EndCanon"):
            continue
        kind = element.get(f"{{{XSI}}}type") or f"{element.tag}Type"
        body = copy.deepcopy(element)
        body.tag = "CRCLCommand"
        body.set(f"{{{XSI}}}type", kind)
        root = etree.Element("CRCLCommandInstance", nsmap={"xsi": XSI})
        root.append(body)
        out.append((kind[:-len("Type")], int(element.findtext("CommandID")),
                    etree.tostring(root, xml_declaration=True, encoding="UTF-8")))
    return out


class FramedClient(RawClient):
    """Sends each document as `framing` says."""

    def __init__(self, port: int, framing: str):
        super().__init__(port, timeout=120)
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.framing = framing
        self.statuses = 0

    def write(self, data: bytes) -> None:
        if self.framing == "byte by byte":
            for byte in data:
                self.send(bytes([byte]))
        elif self.framing == "whitespace between documents":
            self.send(SPACE + data + SPACE)
        else:
            self.send(data)

    def outcome(self, kind: str, command_id: int, document: bytes) -> tuple[str, str]:
        """(CommandState, StateDescription) once the command is Done or Error."""
        poll = command("GetStatus", 900_000 + command_id)
        if self.framing == "command and GetStatus coalesced":
            self.send(document + poll)
        else:
            self.write(document)
            if kind != "GetStatus":
                self.write(poll)
        while True:
            status = self.read_status()        # checked against CRCLStatus.xsd
            self.statuses += 1
            if kind == "GetStatus" or (field(status, "CommandID") == str(command_id) and
                                       field(status, "CommandState") in ("CRCL_Done", "CRCL_Error")):
                return field(status, "CommandState"), field(status, "StateDescription") or ""
            time.sleep(POLL_PERIOD)
            self.write(poll)


def run(client: FramedClient, path, past_errors: bool = False) -> list[tuple]:
    """(CommandID, kind, state, description) of each command run, to the first error unless
    `past_errors`."""
    ran = []
    for kind, command_id, document in instances(path):
        state, description = client.outcome(kind, command_id, document)
        ran.append((command_id, kind, state, description))
        if state == "CRCL_Error" and not past_errors:
            break
    return ran


@needs_xsd
@needs_examples
@pytest.mark.parametrize("framing", FRAMINGS)
@pytest.mark.parametrize("program", sorted(ENDS))
def test_nists_programs_run_to_the_pose_this_cell_forbids_in_every_framing(cell, program,
                                                                          framing):
    client = FramedClient(cell.port, framing)
    try:
        ran = run(client, EXAMPLES / program)
    finally:
        client.close()
    end, why = ENDS[program]
    *before, (command_id, kind, state, description) = ran
    assert (command_id, state) == (end, "CRCL_Error") and description.startswith(why), ran[-1]
    assert all(s == "CRCL_Done" for _, k, s, _ in before if k != "GetStatus"), before
    assert [c for c, *_ in before] == list(range(1, end))
    assert client.statuses >= end


@needs_xsd
@needs_examples
def test_program_all_answers_every_command_on_its_own(cell):
    client = FramedClient(cell.port, FRAMINGS[0])
    try:
        ran = run(client, EXAMPLES / "programAll.xml", past_errors=True)
    finally:
        client.close()
    assert [c for c, *_ in ran] == [1, 2, 3, 4, 5, 6, 7, 8, 9, 12, *range(13, 35)]
    errors = {c: d for c, _, s, d in ran if s == "CRCL_Error"}
    assert set(errors) == set(PROGRAM_ALL_ERRORS), errors
    for command_id, start in PROGRAM_ALL_ERRORS.items():
        assert errors[command_id].startswith(start), (command_id, errors[command_id])
    assert ran[-1][1:3] == ("EndCanon", "CRCL_Done")


@needs_xsd
@needs_examples
def test_nists_command_instances_each_get_their_answer(cell):
    client = FramedClient(cell.port, FRAMINGS[0])
    try:
        assert client.outcome("InitCanon", 1, command("InitCanon", 1))[0] == "CRCL_Done"
        for path in sorted(EXAMPLES.glob("command*.xml")):
            document = path.read_bytes()
            command_id = int(re.search(rb"<CommandID>(\d+)</CommandID>", document).group(1))
            kind = etree.fromstring(document).find("CRCLCommand").get(f"{{{XSI}}}type")[:-4]
            state, description = client.outcome(kind, command_id, document)
            expected = COMMANDS.get(path.name)
            assert state == ("CRCL_Error" if expected else "CRCL_Done"), (path.name, description)
            assert description.startswith(expected or ""), (path.name, description)
            if kind == "EndCanon":
                client.outcome("InitCanon", 1, command("InitCanon", 1))
    finally:
        client.close()


@needs_xsd
def test_the_worked_examples_program_runs_to_its_end(cell):
    client = FramedClient(cell.port, FRAMINGS[0])
    try:
        ran = run(client, ROOT / "examples" / "06_crcl_workstation.xml")
    finally:
        client.close()
    assert [s for *_, s, _ in ran] == ["CRCL_Done"] * 11, ran
    assert "the gripper fetched from the rack" in ran[0][3]
