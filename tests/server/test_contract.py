"""The landscape.v1 contract holds every LandScape command (seed sections 3 to 6)."""
from __future__ import annotations

import pytest

from landscape.server.api import services
from landscape.v1 import types_pb2

# The seed's server commands (sections 3.1 to 3.8) in UpperCamelCase, the extensions a real
# cell needs, the DIGITAL_IO IDL (section 4) and the client IDL (section 2) as streams.
EXPECTED = {
    services.DEVICE: [
        "Lock", "Release", "Activate", "Deactivate",
        "SetSpeed", "SetAcceleration", "SetToolOffset", "SetWorldCartesianFrame", "SetUnits",
        "GetUnits", "GetVelocities", "GetAccelerations", "GetMaxVelocities", "GetMaxAccelerations",
        "GetToolOffsets", "GetWorldCartesianFrame", "GetRobotPosition", "GetMotionControlState", "GetTagId",
        "MoveRelative", "MoveAbsolute", "MoveArc",
        "PathLoad", "PathClearPath", "PathMove",
        "StopMotion", "ResumeMotion", "AbortMotion",
        "GetSensorReading", "MoveReact", "Comply", "ManualControl",
        "GetEndEffectorState", "GetTool", "PutTool", "ActivateTool", "DeactivateTool",
        "SendCommand",
        "Jog", "Reset", "GetDeviceState", "GetRobotDescription", "OperatePanel",
        "GetCellDescription", "ListPaths", "GetPath", "SolvePose",
    ],
    services.DIGITAL_IO: ["SetDigitalIO", "GetDigitalIO", "SignalDigitalIO", "ListDigitalIO"],
    services.EVENTS: ["Subscribe", "PostMessage", "AcknowledgeAlarm"],
    services.SESSIONS: ["Connect"],
    services.STATE: ["StreamState"],
    services.AUDIT: ["ReadAuditLog"],
}

# (client streaming, server streaming)
STREAMING = {"PathLoad": (True, False), "Jog": (True, True), "Subscribe": (False, True),
             "Connect": (True, True), "StreamState": (False, True),
             "GetPath": (False, True), "ReadAuditLog": (False, True)}


@pytest.mark.parametrize("spec", list(EXPECTED), ids=lambda s: s.name)
def test_service_has_exactly_the_expected_rpcs(spec):
    assert sorted(m.name for m in spec.descriptor.methods) == sorted(EXPECTED[spec])


def test_streaming_shapes():
    for spec in EXPECTED:
        for method in spec.descriptor.methods:
            shape = (method.client_streaming, method.server_streaming)
            assert shape == STREAMING.get(method.name, (False, False)), method.full_name


def test_every_response_carries_a_retval():
    for spec in EXPECTED:
        for method in spec.descriptor.methods:
            output = method.output_type
            if method.name in ("Subscribe", "Connect", "StreamState"):
                continue
            assert output.fields_by_name["ret_val"].message_type.full_name == "landscape.v1.RetVal", \
                method.full_name


def test_return_codes_are_the_seeds():
    assert {v.name.removeprefix("RETURN_CODE_"): v.number
            for v in types_pb2.ReturnCode.DESCRIPTOR.values} == {
        "CMD_EXEC_OK": 0, "CMD_STARTED_OK": 1, "CMD_ERR": -1, "CMD_PARAM_ERR": -2,
        "CMD_PARAM_OUT_OF_RANGE_ERR": -3}


@pytest.mark.parametrize("enum, members", [
    (types_pb2.OffsetType, ["ABSOLUTE_DATA", "RELATIVE_DATA"]),
    (types_pb2.ReferenceFrame, ["JOINT_FRAME", "BASE_CARTESIAN_FRAME", "WORLD_CARTESIAN_FRAME",
                                "TOOL_FRAME"]),
    (types_pb2.MotionType, ["JOINT_MOTION", "STRAIGHT_MOTION", "SLEW_MOTION", "CIRCULAR_MOTION"]),
    (types_pb2.SpeedType, ["PERCENT_SPEED", "LINEAR_SPEED", "ANGULAR_SPEED"]),
    (types_pb2.AccelType, ["PERCENT_ACCEL", "LINEAR_ACCEL", "ANGULAR_ACCEL"]),
])
def test_parameter_constants_keep_the_seeds_members(enum, members):
    prefix = enum.DESCRIPTOR.values[0].name.removesuffix("UNSPECIFIED")
    names = [v.name.removeprefix(prefix) for v in enum.DESCRIPTOR.values]
    assert names == ["UNSPECIFIED", *members]


def test_tag_struct_has_the_seeds_fields():
    fields = set(types_pb2.TagStruct.DESCRIPTOR.fields_by_name)
    assert fields == {"x", "y", "z", "roll", "pitch", "yaw", "joint_values", "tag_name", "tag_index",
                      "time_delay", "transition_speed", "speed", "accel", "aux_commands"}
