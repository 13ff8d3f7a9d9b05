"""CRCLStatus documents (CRCLStatus.xsd), from a session's command record, its settings and
the device's live state, in the units last set (spec section VIII).

Elements are written in the schema's order; a part the session turned off, or that the device
cannot say (no live state yet, no tool on the flange), is left out, as the schema allows. A
live state that is old (the state stream stalled or down) is still shown, and StateDescription
says how old. The
tests validate every status written here against CRCLStatus.xsd.
"""
from __future__ import annotations

import functools
import math
from dataclasses import dataclass

from lxml import etree

from landscape.gateway import poses
from landscape.gateway.settings import CrclSettings, SiRate, ToleranceSi
from landscape.gateway.guards import GuardReport
from landscape.gateway.live import LiveState
from landscape.gateway.schemas import NEWEST
from landscape.gateway.units import CrclUnits

XSI = "http://www.w3.org/2001/XMLSchema-instance"
WORKING, DONE, ERROR, READY = "CRCL_Working", "CRCL_Done", "CRCL_Error", "CRCL_Ready"
DEFAULT_GRIPPER_STROKE = 0.08   # m, the default cell's gripper opening (not in landscape.v1)


@dataclass
class CommandRecord:
    """The current or last command other than GetStatus, as CommandStatus reports it."""

    command_id: int = 0
    state: str = READY
    description: str = ""
    program_file: str | None = None
    program_index: int | None = None
    program_length: int | None = None


def number(value: float) -> str:
    """An xs:double: Python's shortest round-trip form, which XML Schema accepts."""
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"{value} has no place in a status")
    return repr(value)


def _add(parent, tag: str, text: str | None = None, xsi_type: str | None = None):
    if xsi_type:
        element = etree.SubElement(parent, tag, nsmap={"xsi": XSI})
        element.set(f"{{{XSI}}}type", xsi_type)
    else:
        element = etree.SubElement(parent, tag)
    if text is not None:
        element.text = text
    return element


def _vector(parent, tag: str, values, names: str = "IJK") -> None:
    element = _add(parent, tag)
    for name, value in zip(names, values):
        _add(element, name, number(value))


def _pose(parent, tag: str, values, units: CrclUnits) -> None:
    """A PoseType of SI values (in CRCL's frame), its Point in `units`."""
    point, x_axis, z_axis = poses.axes(values)
    element = _add(parent, tag)
    _vector(element, "Point", [units.length_out(v) for v in point], names="XYZ")
    _vector(element, "XAxis", x_axis)
    _vector(element, "ZAxis", z_axis)


_HEAD = f"<?xml version='1.0' encoding='UTF-8'?>\n<CRCLStatus xmlns:xsi=\"{XSI}\">".encode()
_TAIL = b"</CRCLStatus>"


def build(record: CommandRecord, status_id: int, settings: CrclSettings,
          live: LiveState | None, stale: str = "",
          gripper_stroke: float = DEFAULT_GRIPPER_STROKE, revision: int = NEWEST,
          guards: GuardReport | None = None) -> bytes:
    """The CRCLStatus document, with its XML declaration, as UTF-8 bytes. `stale`: why the
    live state is not the device's present state (none, or old), added to StateDescription.
    `revision`: of the schemas it is written for (2018 has no sensors and names the end
    tolerance PoseTolerance). `guards`: the last guarded command's, for GuardsStatuses."""
    root = etree.Element("CRCLStatus")       # holds the parts made anew each time
    _command_status(root, record, status_id, stale)
    report = settings.reporting
    arm = b""
    if live is not None:
        arm = _arm(live, settings.units, settings.frame, report.pose, tuple(sorted(
            report.joint_reports.items())) if report.joints else ())
        if report.gripper and live.end_effector and live.end_effector not in settings.grippers_disabled:
            _gripper(root, live, settings, gripper_stroke)
    if report.settings:
        _settings_status(root, settings, revision)
    if report.sensors and live is not None and revision >= NEWEST:
        _sensors(root, settings, live)
    if report.guards and guards is not None and revision >= NEWEST:
        _guards(root, settings.units, guards)
    parts = [etree.tostring(element) for element in root]
    return b"".join((_HEAD, parts[0], arm, *parts[1:], _TAIL))


@functools.lru_cache(maxsize=16)
def _arm(live: LiveState, units: CrclUnits, frame: tuple[float, ...], pose: bool,
         joint_reports: tuple[tuple[int, tuple[bool, bool, bool]], ...]) -> bytes:
    """JointStatuses and PoseStatus (in CRCL's `frame`) of one sample, as reported: made once
    per sample and report, however many clients poll it (the bulk of a status)."""
    root = etree.Element("CRCLStatus")
    if joint_reports:
        _joint_statuses(root, units, joint_reports, live)
    if pose:
        _pose(_add(root, "PoseStatus"), "Pose", poses.to_workstation(live.tool_pose, frame), units)
    return b"".join(etree.tostring(element) for element in root)


def _command_status(root, record: CommandRecord, status_id: int, stale: str) -> None:
    status = _add(root, "CommandStatus")
    _add(status, "CommandID", str(record.command_id))
    _add(status, "StatusID", str(status_id))
    _add(status, "CommandState", record.state)
    description = "; ".join(d for d in (record.description, stale) if d)
    if description:
        _add(status, "StateDescription", description)
    if record.program_file is not None:
        _add(status, "ProgramFile", record.program_file)
    if record.program_index is not None:
        _add(status, "ProgramIndex", str(record.program_index))
    if record.program_length is not None:
        _add(status, "ProgramLength", str(record.program_length))


def _joint_statuses(root, units: CrclUnits, joint_reports, live: LiveState) -> None:
    rows = [(j, flags) for j, flags in joint_reports
            if j <= len(live.joint_positions) and any(flags)]
    if not rows:
        return
    statuses = _add(root, "JointStatuses")
    for joint, (position, torque, velocity) in rows:
        status = _add(statuses, "JointStatus")
        _add(status, "JointNumber", str(joint))
        if position:
            _add(status, "JointPosition", number(units.angle_out(live.joint_positions[joint - 1])))
        if torque and len(live.joint_torques) >= joint:
            _add(status, "JointTorqueOrForce",
                 number(units.torque_out(live.joint_torques[joint - 1])))
        if velocity and len(live.joint_velocities) >= joint:
            _add(status, "JointVelocity", number(units.angle_out(live.joint_velocities[joint - 1])))


def _gripper(root, live: LiveState, settings: CrclSettings, stroke: float) -> None:
    state = live.end_effector_state
    name = "".join(ch for ch in live.end_effector if ch.isalnum() or ch in "._-:") or "tool"
    if is_vacuum(live.end_effector, state):
        gripper = _add(root, "GripperStatus", xsi_type="VacuumGripperStatusType")
        _add(gripper, "GripperName", name)
        _add(gripper, "HoldingObject", "true" if "holding" in state or state == "vacuum_ok" else "false")
        _add(gripper, "IsPowered", "true" if "on" in state.split("_") else "false")
        return
    gripper = _add(root, "GripperStatus", xsi_type="ParallelGripperStatusType")
    _add(gripper, "GripperName", name)
    _add(gripper, "HoldingObject", "true" if state == "holding" else "false")
    opening = stroke if state == "open" else 0.0
    _add(gripper, "Separation", number(settings.units.length_out(opening)))


def is_vacuum(tool: str, state: str) -> bool:
    """landscape.v1 names the tool and its state, not its kind: a vacuum tool says so."""
    return "vacuum" in tool.lower() or "cup" in tool.lower() or state.startswith("vacuum")


def _tolerance(parent, tag: str, t: ToleranceSi, settings: CrclSettings) -> None:
    if all(v is None for v in (t.x, t.y, t.z, t.x_axis, t.z_axis)):
        return
    units = settings.units
    element = _add(parent, tag)
    for name, value, out in (("XPointTolerance", t.x, units.length_out),
                             ("YPointTolerance", t.y, units.length_out),
                             ("ZPointTolerance", t.z, units.length_out),
                             ("XAxisTolerance", t.x_axis, units.angle_out),
                             ("ZAxisTolerance", t.z_axis, units.angle_out)):
        if value is not None:
            _add(element, name, number(out(value)))


def _parameters(parent, tag: str, values: dict[str, str]) -> None:
    for name, value in values.items():
        setting = _add(parent, tag)
        _add(setting, "ParameterName", name)
        _add(setting, "ParameterValue", value)


def _rate(parent, tag: str, rate: SiRate, out) -> None:
    if rate.absolute is not None:
        _add(_add(parent, f"{tag}Absolute"), "Setting", number(out(rate.absolute)))


def _rate_relative(parent, tag: str, rate: SiRate) -> None:
    if rate.fraction is not None:
        _add(_add(parent, f"{tag}Relative"), "Fraction", number(rate.fraction))


def _settings_status(root, s: CrclSettings, revision: int) -> None:
    units = s.units
    element = _add(root, "SettingsStatus")
    _add(element, "AngleUnitName", units.angle)
    _parameters(element, "EndEffectorParameterSetting", s.end_effector_parameters)
    if s.end_effector_setting is not None:
        _add(element, "EndEffectorSetting", number(s.end_effector_setting))
    _add(element, "ForceUnitName", units.force)
    _tolerance(element, "IntermediatePoseTolerance", s.intermediate_tolerance, s)
    _add(element, "LengthUnitName", units.length)
    _add(element, "MotionCoordinated", "true" if s.coordinated else "false")
    _tolerance(element, "EndPoseTolerance" if revision >= NEWEST else "PoseTolerance",
               s.end_tolerance, s)
    _parameters(element, "RobotParameterSetting",
                {k: v for k, v in s.robot_parameters.items() if k in s.reported_parameters})
    # Schema order: RotAccelAbsolute, RotAccelRelative, RotSpeedAbsolute, RotSpeedRelative, ...
    for tag, rate, out in (("RotAccel", s.rot_accel, units.angle_out),
                           ("RotSpeed", s.rot_speed, units.angle_out)):
        _rate(element, tag, rate, out)
        _rate_relative(element, tag, rate)
    _add(element, "TorqueUnitName", units.torque)
    for tag, rate in (("TransAccel", s.trans_accel), ("TransSpeed", s.trans_speed)):
        _rate(element, tag, rate, units.length_out)
        _rate_relative(element, tag, rate)
    if s.joint_tolerances and revision >= NEWEST:
        tolerances = _add(element, "JointTolerances")
        for joint, value in sorted(s.joint_tolerances.items()):
            setting = _add(tolerances, "Setting")
            _add(setting, "JointNumber", str(joint))
            _add(setting, "JointPositionTolerance", number(units.angle_out(value)))


def _sensors(root, settings: CrclSettings, live: LiveState) -> None:
    readings = [(name, live.sensors[name]) for name in sorted(settings.sensors)
                if name in live.sensors]
    if not readings:
        return
    units = settings.units
    element = _add(root, "SensorStatuses")
    scalars, forces = [], []
    for name, values in readings:
        (forces if len(values) == 6 else scalars).append((name, values))
    for name, values in scalars:
        sensor = _sensor(element, "ScalarSensorStatus", name, live)
        _add(sensor, "ScalarValue.", number(units.length_out(values[0]) if values else 0.0))
    for name, values in forces:
        sensor = _sensor(element, "ForceTorqueSensorStatus", name, live)
        for tag, value in zip(("Fx", "Fy", "Fz"), values[:3]):
            _add(sensor, tag, number(units.force_out(value)))
        for tag, value in zip(("Tx", "Ty", "Tz"), values[3:]):
            _add(sensor, tag, number(units.torque_out(value)))


def _guards(root, units: CrclUnits, report: GuardReport) -> None:
    element = _add(root, "GuardsStatuses")
    for guard in report.guards:
        written = _add(element, "Guard")
        _add(written, "SensorID", guard.sensor_id)
        if guard.sub_field is not None:
            _add(written, "SubField", guard.sub_field)
        _add(written, "LimitType", guard.limit_type)
        _add(written, "LimitValue", number(guard.limit_value))
    _add(element, "TriggerCount", str(report.trigger_count))
    _add(element, "TriggerStopTimeMicros", str(report.stop_time_us))
    if report.value is not None:
        _add(element, "TriggerValue", number(report.value))
    if report.pose is not None:
        _pose(element, "TriggerPose", report.pose, units)


def _sensor(parent, tag: str, name: str, live: LiveState):
    sensor = _add(parent, tag)
    _add(sensor, "SensorID", name)
    _add(sensor, "ReadCount", str(live.sequence % 2**31))
    _add(sensor, "LastReadTime", str(int(live.time * 1e3)))   # ms since 1970 (the schema)
    return sensor
