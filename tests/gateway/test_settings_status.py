"""Settings and reporting (the 2021 revision's commands among them): Done for the very next
GetStatus, and reported in SettingsStatus in the units in force."""
from __future__ import annotations

import pytest

from crcl_support import XSD_2021, command, field

CRCL_SCHEMAS = XSD_2021       # EnableRobotParameterStatus, ReportSensorsStatus, ...: 2021's


def test_settings_status_reports_what_was_set_in_current_units(client):
    client.run("InitCanon", 1)
    client.run("ConfigureStatusReport", 2, "".join(
        f"<{t}>{v}</{t}>" for t, v in (("ReportJointStatuses", "false"), ("ReportPoseStatus", "true"),
                                       ("ReportGripperStatus", "true"), ("ReportSettingsStatus", "true"),
                                       ("ReportSensorsStatus", "false"), ("ReportGuardsStatus", "false"))))
    client.run("SetTransSpeed", 3, '<TransSpeed xsi:type="TransSpeedAbsoluteType">'
                                   '<Setting>0.2</Setting></TransSpeed>')
    client.run("SetLengthUnits", 4, "<UnitName>millimeter</UnitName>")
    client.run("SetEndPoseTolerance", 5, "<Tolerance><XPointTolerance>1</XPointTolerance></Tolerance>")
    status = client.status()
    assert field(status, "JointStatuses") is None
    assert float(field(field(status, "TransSpeedAbsolute"), "Setting")) == pytest.approx(200.0)
    assert float(field(status, "XPointTolerance")) == pytest.approx(1.0)
    assert field(status, "LengthUnitName") == "millimeter"


TOLERANCE = "<Tolerance><XPointTolerance>0.001</XPointTolerance></Tolerance>"
RATE = '<{0} xsi:type="{0}RelativeType"><Fraction>0.5</Fraction></{0}>'
IMMEDIATE_SAMPLES = {
    "SetAngleUnits": "<UnitName>degree</UnitName>", "SetLengthUnits": "<UnitName>millimeter</UnitName>",
    "SetForceUnits": "<UnitName>newton</UnitName>",
    "SetTorqueUnits": "<UnitName>newtonMeter</UnitName>",
    "SetTransSpeed": RATE.format("TransSpeed"), "SetRotSpeed": RATE.format("RotSpeed"),
    "SetTransAccel": RATE.format("TransAccel"), "SetRotAccel": RATE.format("RotAccel"),
    "SetEndPoseTolerance": TOLERANCE, "SetIntermediatePoseTolerance": TOLERANCE,
    # (the schema spells it so)
    "SetDefaultJointPositonsTolerances": "<JointTolerances><Setting><JointNumber>1</JointNumber>"
                                          "<JointPositionTolerance>0.01</JointPositionTolerance>"
                                          "</Setting></JointTolerances>",
    "SetMotionCoordination": "<Coordinated>true</Coordinated>",
    "ConfigureJointReports": "<ResetAll>true</ResetAll>",
    "ConfigureStatusReport": "".join(f"<Report{t}>true</Report{t}>" for t in (
        "JointStatuses", "PoseStatus", "GripperStatus", "SettingsStatus", "SensorsStatus",
        "GuardsStatus")),
    "EnableRobotParameterStatus": "<RobotParameterName>ToolOffset</RobotParameterName>",
    "DisableRobotParameterStatus": "<RobotParameterName>ToolOffset</RobotParameterName>",
    "EnableGripper": "<GripperName>gripper</GripperName>",
    "DisableGripper": "<GripperName>gripper</GripperName>",
    "Dwell": "<DwellTime>0</DwellTime>",
}


def test_settings_are_done_for_the_very_next_get_status(client):
    """Commands carried out without the device are Done before the next document is read:
    a client polling at once after them needs one GetStatus (NIST's reference client's
    pattern, and the CRCL bench's)."""
    from landscape.gateway.handlers import IMMEDIATE
    assert {c.KIND for c in IMMEDIATE} | {"Dwell"} == set(IMMEDIATE_SAMPLES)
    client.run("InitCanon", 1)
    for command_id, (kind, body) in enumerate(IMMEDIATE_SAMPLES.items(), start=2):
        client.send(command(kind, command_id, body) + command("GetStatus", 900 + command_id))
        status = client.read_status()
        assert (field(status, "CommandID"), field(status, "CommandState")) == (
            str(command_id), "CRCL_Done"), status
