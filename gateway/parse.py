"""The gateway's own typed parser of CRCL documents (model.py), written from the specification.

It checks what the gateway relies on whether or not the schemas are configured: the element
sequence of every type (required, optional, repeated, nothing unknown), the xsi:type of every
polymorphic element, XML Schema's lexical forms of the numbers and booleans (not Python's:
float("1_0") and float("infinity") are not xs:double), and the ranges the specification states
(fractions in 0..1, unit names, positive joint numbers, unit and orthogonal pose axes). Every
error names the line and the element: "line 12: <JointNumber>: ...".
"""
from __future__ import annotations

import math

from lxml import etree

from landscape.gateway import model as m
from landscape.gateway.xsd_lexical import (CrclParseError, enum_of, fail, local_name, fraction,
                                           joint_number, non_negative, positive, xs_boolean,
                                           xs_double, xs_int, xs_long, xs_string, xs_token)

XSI_TYPE = "{http://www.w3.org/2001/XMLSchema-instance}type"


# ---- the element sequence of one type ----------------------------------------------------------------

class Children:
    """Reads an element's children in schema order: each call takes the next matching ones."""

    def __init__(self, element):
        self.parent = element
        self.items = [child for child in element if isinstance(child.tag, str)]
        for child in self.items:
            if child.tag.startswith("{"):
                fail(child, "CRCL elements have no namespace")
        self.i = 0

    def optional(self, tag: str, read):
        if self.i < len(self.items) and self.items[self.i].tag == tag:
            self.i += 1
            return read(self.items[self.i - 1])
        return None

    def required(self, tag: str, read):
        if self.i >= len(self.items) or self.items[self.i].tag != tag:
            found = (f"found <{self.items[self.i].tag}>" if self.i < len(self.items)
                     else "it ends")
            fail(self.parent, f"expected <{tag}>, {found}")
        return self.optional(tag, read)

    def many(self, tag: str, read, minimum: int = 0) -> tuple:
        values = []
        while (value := self.optional(tag, read)) is not None:
            values.append(value)
        if len(values) < minimum:
            fail(self.parent, f"needs at least {minimum} <{tag}>, found {len(values)}")
        return tuple(values)

    def done(self) -> None:
        if self.i < len(self.items):
            fail(self.items[self.i], "unexpected element here")


def _xsi_type(element, allowed: dict, default=None):
    value = element.get(XSI_TYPE)
    if value is None:
        if default is None:
            fail(element, f"needs xsi:type, one of {', '.join(allowed)}")
        return default
    value = value.split(":")[-1].strip()
    if value not in allowed:
        fail(element, f"xsi:type {value!r} is none of {', '.join(allowed)}")
    return allowed[value]


def _name(c: Children) -> str | None:
    return c.optional("Name", xs_string)


# ---- data primitives ----------------------------------------------------------------------------------

def point(element) -> m.Point:
    c = Children(element)
    _name(c)
    value = m.Point(c.required("X", xs_double), c.required("Y", xs_double),
                    c.required("Z", xs_double))
    c.done()
    return value


def vector(element) -> m.Vector:
    c = Children(element)
    _name(c)
    value = m.Vector(c.required("I", xs_double), c.required("J", xs_double),
                     c.required("K", xs_double))
    c.done()
    return value


def _rate(kind: str):
    types = {f"{kind}AbsoluteType": "absolute", f"{kind}RelativeType": "relative"}

    def read(element) -> m.Rate:
        which = _xsi_type(element, types)
        c = Children(element)
        _name(c)
        rate = (m.Rate(absolute=c.required("Setting", positive)) if which == "absolute"
                else m.Rate(fraction=c.required("Fraction", fraction)))
        c.done()
        return rate
    return read


def pose_tolerance(element) -> m.PoseTolerance:
    c = Children(element)
    _name(c)
    value = m.PoseTolerance(*(c.optional(tag, non_negative) for tag in (
        "XPointTolerance", "YPointTolerance", "ZPointTolerance", "XAxisTolerance",
        "ZAxisTolerance")))
    c.done()
    return value


AXIS_TOLERANCE = 1e-3   # |x.z| and | |v| - 1 | above this are refused


def pose(element) -> m.Pose:
    kind = _xsi_type(element, {"PoseType": "pose", "PoseAndSetType": "set"}, default="pose")
    c = Children(element)
    _name(c)
    p = c.required("Point", point)
    x_axis, z_axis = c.required("XAxis", vector), c.required("ZAxis", vector)
    settings = None
    if kind == "set":
        settings = m.PoseSettings(
            c.required("Coordinated", xs_boolean), c.optional("TransSpeed", _rate("TransSpeed")),
            c.optional("RotSpeed", _rate("RotSpeed")), c.optional("TransAccel", _rate("TransAccel")),
            c.optional("RotAccel", _rate("RotAccel")), c.optional("Tolerance", pose_tolerance))
    c.done()
    _check_axes(element, x_axis, z_axis)
    return m.Pose(p, x_axis, z_axis, settings)


def _check_axes(element, x: m.Vector, z: m.Vector) -> None:
    nx, nz = math.hypot(x.i, x.j, x.k), math.hypot(z.i, z.j, z.k)
    for name, norm in (("XAxis", nx), ("ZAxis", nz)):
        if abs(norm - 1.0) > AXIS_TOLERANCE:
            fail(element, f"{name} must be a unit vector, its length is {norm:.6g}")
    dot = (x.i * z.i + x.j * z.j + x.k * z.k) / (nx * nz)
    if abs(dot) > AXIS_TOLERANCE:
        fail(element, f"XAxis and ZAxis must be orthogonal, their dot product is {dot:.6g}")


def parameter_setting(element) -> m.ParameterSetting:
    c = Children(element)
    _name(c)
    value = m.ParameterSetting(c.required("ParameterName", xs_token),
                               c.required("ParameterValue", xs_token))
    c.done()
    return value


def _joint_tolerance(element) -> m.JointTolerance:
    c = Children(element)
    _name(c)
    value = m.JointTolerance(c.required("JointNumber", joint_number),
                             c.required("JointPositionTolerance", non_negative))
    c.done()
    return value


def joint_tolerances(element) -> tuple[m.JointTolerance, ...]:
    c = Children(element)
    _name(c)
    values = c.many("Setting", _joint_tolerance, minimum=1)
    c.done()
    _unique_joints(element, [t.joint for t in values])
    return values


def _unique_joints(element, joints: list[int]) -> None:
    if len(set(joints)) != len(joints):
        fail(element, f"a joint appears more than once: {joints}")


def guard(element) -> m.Guard:
    c = Children(element)
    _name(c)
    value = m.Guard(
        sensor_id=c.required("SensorID", xs_token), sub_field=c.optional("SubField", xs_token),
        limit_type=c.required("LimitType", enum_of("OVER_MAX", "UNDER_MIN", "INCREASE_OVER_LIMIT",
                                                 "DECREASE_BEYOND_LIMIT")),
        limit_value=c.required("LimitValue", xs_double),
        recheck_time_us=c.optional("RecheckTimeMicroSeconds", xs_long),
        check_count=c.optional("CheckCount", xs_long),
        last_check_time=c.optional("LastCheckTime", xs_long),
        last_check_value=c.optional("LastCheckValue", xs_double),
        require_trigger=c.optional("RequireTrigger", xs_boolean),
        error_on_trigger=c.optional("ErrorOnTrigger", xs_boolean))
    c.done()
    return value


def _joint_details(element):
    kind = _xsi_type(element, {"JointSpeedAccelType": "speed", "JointForceTorqueType": "force"})
    c = Children(element)
    _name(c)
    if kind == "speed":
        value = m.JointSpeedAccel(c.optional("JointSpeed", positive),
                                  c.optional("JointAccel", positive))
    else:
        value = m.JointForceTorque(c.optional("Setting", xs_double),
                                   c.optional("ChangeRate", xs_double))
    c.done()
    return value


def _actuate_joint(element) -> m.ActuateJoint:
    c = Children(element)
    _name(c)
    value = m.ActuateJoint(c.required("JointNumber", joint_number),
                           c.required("JointPosition", xs_double),
                           c.required("JointDetails", _joint_details))
    c.done()
    return value


def _joint_report(element) -> m.JointReport:
    c = Children(element)
    _name(c)
    value = m.JointReport(c.required("JointNumber", joint_number),
                          c.required("ReportPosition", xs_boolean),
                          c.required("ReportTorqueOrForce", xs_boolean),
                          c.required("ReportVelocity", xs_boolean))
    c.done()
    return value


# ---- commands ---------------------------------------------------------------------------------------------

UNIT_NAMES = {"length": ("meter", "millimeter", "inch"), "angle": ("degree", "radian"),
              "force": ("newton", "pound", "ounce"), "torque": ("newtonMeter", "footPound")}


def _fields(cls, c: Children, element) -> dict:
    """The fields of command class `cls` from the children after CommandID and Guard."""
    if issubclass(cls, m.SetUnits):
        return {"unit": c.required("UnitName", enum_of(*UNIT_NAMES[cls.QUANTITY]))}
    if issubclass(cls, m.SetRate):
        return {"rate": c.required(cls.QUANTITY, _rate(cls.QUANTITY))}
    reader = _READERS.get(cls)
    return reader(c, element) if reader else {}


def _actuate_joints(c, element):
    joints = c.many("ActuateJoint", _actuate_joint, minimum=1)
    _unique_joints(element, [j.joint for j in joints])
    return {"joints": joints, "tolerances": c.optional("JointTolerances", joint_tolerances)}


def _configure_joint_reports(c, element):
    reset_all = c.required("ResetAll", xs_boolean)
    reports = c.many("ConfigureJointReport", _joint_report)
    joints = [r.joint for r in reports]
    _unique_joints(element, joints)
    if joints != sorted(joints):
        fail(element, f"joint numbers must be given in increasing order, got {joints}")
    return {"reset_all": reset_all, "reports": reports}


def _configure_status_report(c, element):
    """The 2021 revision's six flags, or the 2018 revision's first four (no sensors, no
    guards to report)."""
    tags = ("ReportJointStatuses", "ReportPoseStatus", "ReportGripperStatus",
            "ReportSettingsStatus")
    values = [c.required(tag, xs_boolean) for tag in tags]
    sensors = c.optional("ReportSensorsStatus", xs_boolean)
    values += [bool(sensors), sensors is not None and c.required("ReportGuardsStatus", xs_boolean)]
    return dict(zip(("report_joints", "report_pose", "report_gripper", "report_settings",
                     "report_sensors", "report_guards"), values))


def _move_screw(c, element):
    return {"start": c.optional("StartPosition", pose),
            "axis_point": c.optional("AxisPoint", point),
            "axial_distance_free": c.optional("AxialDistanceFree", xs_double),
            "axial_distance_screw": c.required("AxialDistanceScrew", xs_double),
            "turn": c.required("Turn", xs_double)}


def _move_through_to(c, element):
    straight = c.required("MoveStraight", xs_boolean)
    waypoints = c.many("Waypoint", pose, minimum=2)
    count = c.required("NumPositions", xs_int)
    if count != len(waypoints):
        fail(element, f"NumPositions says {count}, there are {len(waypoints)} waypoints")
    return {"straight": straight, "waypoints": waypoints, "num_positions": count}


def _one(tag: str, field: str, read):
    return lambda c, element: {field: c.required(tag, read)}


def _settings(tag: str):
    return lambda c, element: {"settings": c.many(tag, parameter_setting, minimum=1)}


def _with_options(id_tag, id_field, option_tag, id_read):
    return lambda c, element: {id_field: c.required(id_tag, id_read),
                               "options": c.many(option_tag, parameter_setting)}


_READERS = {
    m.ActuateJoints: _actuate_joints,
    m.ConfigureJointReports: _configure_joint_reports,
    m.ConfigureStatusReport: _configure_status_report,
    m.Dwell: _one("DwellTime", "seconds", non_negative),
    m.Message: _one("Message", "text", xs_string),
    m.MoveScrew: _move_screw,
    m.MoveThroughTo: _move_through_to,
    m.MoveTo: lambda c, element: {"straight": c.required("MoveStraight", xs_boolean),
                                  "end": c.required("EndPosition", pose)},
    m.RunProgram: _one("ProgramText", "text", xs_string),
    m.SetEndEffectorParameters: _settings("ParameterSetting"),
    m.SetEndEffector: _one("Setting", "setting", fraction),
    m.SetEndPoseTolerance: _one("Tolerance", "tolerance", pose_tolerance),
    m.SetIntermediatePoseTolerance: _one("Tolerance", "tolerance", pose_tolerance),
    m.SetDefaultJointPositionsTolerances: _one("JointTolerances", "tolerances",
                                               joint_tolerances),
    m.SetMotionCoordination: _one("Coordinated", "coordinated", xs_boolean),
    m.SetRobotParameters: _settings("ParameterSetting"),
    m.StopMotion: _one("StopCondition", "condition", enum_of("Immediate", "Fast", "Normal")),
    m.EnableSensor: _with_options("SensorID", "sensor_id", "SensorOption", xs_token),
    m.DisableSensor: _one("SensorID", "sensor_id", xs_token),
    m.EnableGripper: _with_options("GripperName", "gripper_name", "GripperOption", xs_token),
    m.DisableGripper: _one("GripperName", "gripper_name", xs_token),
    m.EnableRobotParameterStatus: _one("RobotParameterName", "parameter", xs_token),
    m.DisableRobotParameterStatus: _one("RobotParameterName", "parameter", xs_token),
    m.LoopBlockStart: _one("LoopName", "loop_name", xs_string),
    m.LoopBlockEnd: lambda c, element: {"loop_name": c.required("LoopName", xs_string),
                                        "max_count": c.required("MaxCount", xs_int)},
}

_MIDDLE = {k: v for k, v in m.COMMAND_TYPES.items()
           if v not in (m.InitCanon, m.EndCanon)}


def command(element, allowed: dict | None = None, fixed: type | None = None) -> m.Command:
    """A command element: its class from xsi:type (or `fixed`), then its fields."""
    cls = fixed or _xsi_type(element, allowed or m.COMMAND_TYPES)
    c = Children(element)
    name = _name(c)
    command_id = c.required("CommandID", xs_long)
    guards = c.many("Guard", guard)
    fields = _fields(cls, c, element)
    c.done()
    return cls(command_id=command_id, name=name, guards=guards, **fields)


# ---- documents ------------------------------------------------------------------------------------------

def document(tree: etree._ElementTree) -> m.CommandInstance | m.Program:
    root = tree.getroot()
    if root.tag == "CRCLCommandInstance":
        return command_instance(root)
    if root.tag == "CRCLProgram":
        return program(root)
    fail(root, "the root must be CRCLCommandInstance or CRCLProgram")


def command_instance(root) -> m.CommandInstance:
    c = Children(root)
    _name(c)
    cmd = c.required("CRCLCommand", command)
    instance = m.CommandInstance(cmd, c.optional("ProgramFile", xs_string),
                                 c.optional("ProgramIndex", xs_int),
                                 c.optional("ProgramLength", xs_int))
    c.done()
    return instance


def program(root) -> m.Program:
    c = Children(root)
    name = _name(c)
    init = c.required("InitCanon", lambda e: command(e, fixed=m.InitCanon))
    middle = c.many("MiddleCommand", lambda e: command(e, _MIDDLE))
    end = c.required("EndCanon", lambda e: command(e, fixed=m.EndCanon))
    c.done()
    return m.Program((init, *middle, end), name)
