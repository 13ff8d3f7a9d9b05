"""The optional elements a program may carry, each carried out where the device can and refused
with a CRCL_Error naming it where it cannot (issue 27 item 3; docs/crcl.md's table names these
tests): joint reports, robot parameter reports, gripper reports and options, force units in
sensor statuses, per-command joint tolerances, loop blocks, NumPositions. The arm holds the
gripper from InitCanon on (NIST's 2021 revision: some of these are only there)."""
from __future__ import annotations

import re

import pytest

from landscape.gateway.workstation import Workstation

from crcl_support import XSD_2021, command, field, pose, program
from test_gateway import MOVE

CRCL_SCHEMAS = XSD_2021
CRCL_WORKSTATION = Workstation(end_effector="gripper")
REPORT_ALL = "".join(f"<Report{t}>true</Report{t}>" for t in (
    "JointStatuses", "PoseStatus", "GripperStatus", "SettingsStatus", "SensorsStatus",
    "GuardsStatus"))


def _done(status: str) -> str:
    assert field(status, "CommandState") == "CRCL_Done", status
    return status


def _refused(status: str) -> str:
    assert field(status, "CommandState") == "CRCL_Error", status
    return field(status, "StateDescription")


def _joint(status: str, number: int) -> str:
    return next(j for j in re.findall(r"<JointStatus>(.*?)</JointStatus>", status)
                if f"<JointNumber>{number}</JointNumber>" in j)


def test_joint_reports_say_what_each_joint_asks_for(client):
    _done(client.run("ConfigureJointReports", 2, "<ResetAll>true</ResetAll>" + "".join(
        f"<ConfigureJointReport><JointNumber>{j}</JointNumber><ReportPosition>{p}"
        f"</ReportPosition><ReportTorqueOrForce>{t}</ReportTorqueOrForce><ReportVelocity>{v}"
        f"</ReportVelocity></ConfigureJointReport>"
        for j, p, t, v in ((2, "true", "true", "true"), (5, "false", "false", "true")))))
    client.send(command("MoveTo", 3, MOVE.format("false") + pose(0.5, 0.2, 0.6)))
    status = client.status()
    assert re.findall(r"<JointNumber>(\d)</JointNumber>", status) == ["2", "5"]
    two, five = _joint(status, 2), _joint(status, 5)
    assert field(two, "JointPosition") and field(five, "JointPosition") is None
    assert abs(float(field(two, "JointTorqueOrForce"))) > 1.0      # the shoulder holds the arm
    assert field(five, "JointVelocity") is not None and field(five, "JointTorqueOrForce") is None
    _done(client.wait_done(3))


def test_robot_parameters_are_reported_once_enabled(client):
    _done(client.run("ConfigureStatusReport", 2, REPORT_ALL))
    _done(client.run("SetRobotParameters", 3, "<ParameterSetting><ParameterName>WorkstationFrame"
                     "</ParameterName><ParameterValue>0 0 0.01 0 0 0</ParameterValue>"
                     "</ParameterSetting>"))
    assert "RobotParameterSetting" not in client.status()
    _done(client.run("EnableRobotParameterStatus", 4,
                     "<RobotParameterName>WorkstationFrame</RobotParameterName>"))
    setting = field(client.status(), "RobotParameterSetting")
    assert field(setting, "ParameterValue") == "0 0 0.01 0 0 0"
    _done(client.run("DisableRobotParameterStatus", 5,
                     "<RobotParameterName>WorkstationFrame</RobotParameterName>"))
    assert "RobotParameterSetting" not in client.status()
    assert _refused(client.run("EnableRobotParameterStatus", 6, "<RobotParameterName>empathy"
                               "</RobotParameterName>")).startswith(
        "unknown robot parameter 'empathy'; known: ToolOffset, WorkstationFrame")


def test_a_gripper_is_reported_until_disabled_and_options_are_refused(client):
    assert "<GripperName>gripper</GripperName>" in client.status()
    _done(client.run("DisableGripper", 2, "<GripperName>gripper</GripperName>"))
    assert "GripperStatus" not in client.status()
    _done(client.run("EnableGripper", 3, "<GripperName>gripper</GripperName>"))
    assert "<GripperName>gripper</GripperName>" in client.status()
    assert _refused(client.run("EnableGripper", 4, "<GripperName>gripper</GripperName>"
                               "<GripperOption><ParameterName>force</ParameterName>"
                               "<ParameterValue>40</ParameterValue></GripperOption>")) == \
        "GripperOption (force): landscape.v1 tools take no options"


def test_sensor_statuses_follow_the_force_units(client):
    _done(client.run("EnableSensor", 2, "<SensorID>force_sensor</SensorID>"))
    newtons = float(field(client.status(), "Fz"))
    assert newtons == pytest.approx(1.2 * 9.81, abs=1.0)          # the gripper hangs there
    _done(client.run("SetForceUnits", 3, "<UnitName>pound</UnitName>"))
    assert float(field(client.status(), "Fz")) == pytest.approx(newtons / 4.4482216, rel=0.05)


def test_an_actuate_joints_own_tolerance_judges_its_end(client):
    body = ('<ActuateJoint><JointNumber>1</JointNumber><JointPosition>0.2</JointPosition>'
            '<JointDetails xsi:type="JointSpeedAccelType"></JointDetails></ActuateJoint>'
            "<JointTolerances><Setting><JointNumber>1</JointNumber><JointPositionTolerance>"
            "{}</JointPositionTolerance></Setting></JointTolerances>")
    _done(client.run("ActuateJoints", 2, body.format("0.001")))
    assert _refused(client.run("ActuateJoints", 3, body.format("1e-15").replace(
        ">0.2<", ">0.3<"))).startswith("joint 1 ended ")


def test_loop_blocks_repeat_in_a_program_and_mean_nothing_alone(client):
    looped = program([("LoopBlockStart", "<LoopName>three</LoopName>"),
                      ("Dwell", "<DwellTime>0</DwellTime>"),
                      ("LoopBlockEnd", "<LoopName>three</LoopName><MaxCount>3</MaxCount>")])
    client.send(looped)
    done = _done(client.wait_done(5))
    assert field(done, "StateDescription") == "program done: 5 commands"   # InitCanon, 3, End
    client.run("InitCanon", 6)
    assert _refused(client.run("LoopBlockStart", 7, "<LoopName>x</LoopName>")).startswith(
        "LoopBlockStart belongs in a CRCLProgram")


def test_num_positions_must_count_the_waypoints(client):
    body = (MOVE.format("false") + pose(0.5, 0.1, 0.6, tag="Waypoint") +
            pose(0.5, 0.2, 0.6, tag="Waypoint") + "<NumPositions>3</NumPositions>")
    said = _refused(client.run("MoveThroughTo", 2, body))
    assert "NumPositions says 3, there are 2 waypoints" in said
