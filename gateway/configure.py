"""CRCL commands that change the session's settings or reporting, or wait (no device motion)."""
from __future__ import annotations

import asyncio

from landscape.gateway import model as m
from landscape.gateway.errors import CrclError
from landscape.gateway.settings import DEFAULT_END_TOLERANCE, JOINTS, rate_si, tolerance_si
from landscape.gateway.workstation import pose_values

_RATE_FIELDS = {"TransSpeed": ("trans_speed", "length", "linear_speed"),
                "RotSpeed": ("rot_speed", "angle", "angular_speed"),
                "TransAccel": ("trans_accel", "length", "linear_accel"),
                "RotAccel": ("rot_accel", "angle", "angular_accel")}


async def set_units(session, cmd: m.SetUnits) -> str:
    session.settings.units = session.settings.units.with_unit(cmd.QUANTITY, cmd.unit)
    return f"{cmd.QUANTITY} units: {cmd.unit}"


async def set_rate(session, cmd: m.SetRate) -> str:
    field, quantity, limit = _RATE_FIELDS[cmd.QUANTITY]
    units = session.settings.units
    scale = units.length_si(1.0) if quantity == "length" else units.angle_si(1.0)
    rate = rate_si(cmd.rate, scale)
    if not (rate.absolute or rate.fraction or 0.0) > 0.0:
        raise CrclError(f"{cmd.QUANTITY} must be above 0")
    setattr(session.settings, field, rate)      # on the device before the next motion
    maximum = getattr(session.control.limits, limit)
    if rate.absolute is not None and rate.absolute > maximum:
        out = units.length_out if quantity == "length" else units.angle_out
        unit = f"{getattr(units, quantity)}/s{'^2' if 'Accel' in cmd.QUANTITY else ''}"
        return f"{cmd.QUANTITY} limited to the arm's maximum, {out(maximum):.6g} {unit}"
    return f"{cmd.QUANTITY} set"


async def set_end_pose_tolerance(session, cmd: m.SetEndPoseTolerance) -> str:
    # An element left out keeps the default (DEFAULT_END_TOLERANCE), never "any end".
    session.settings.end_tolerance = tolerance_si(cmd.tolerance, session.settings.units).over(
        DEFAULT_END_TOLERANCE)
    return "end pose tolerance set"


async def set_intermediate_pose_tolerance(session, cmd: m.SetIntermediatePoseTolerance) -> str:
    session.settings.intermediate_tolerance = tolerance_si(cmd.tolerance, session.settings.units)
    return "intermediate pose tolerance set (the device's paths pass through every waypoint)"


def _check_joint(joint: int) -> None:
    if joint > JOINTS:
        raise CrclError(f"joint {joint}: the arm has joints 1 to {JOINTS}")


async def set_default_joint_tolerances(session, cmd: m.SetDefaultJointPositionsTolerances) -> str:
    for t in cmd.tolerances:
        _check_joint(t.joint)
    units = session.settings.units
    session.settings.joint_tolerances.update(
        {t.joint: units.angle_si(t.tolerance) for t in cmd.tolerances})
    return "default joint tolerances set"


async def set_motion_coordination(session, cmd: m.SetMotionCoordination) -> str:
    # The device always finishes rotation and translation together, which both settings allow.
    session.settings.coordinated = cmd.coordinated
    return "motion coordination set (the device's motions are always coordinated)"


async def configure_joint_reports(session, cmd: m.ConfigureJointReports) -> str:
    for report in cmd.reports:
        _check_joint(report.joint)
    reports = session.settings.reporting.joint_reports
    if cmd.reset_all:
        reports.clear()
    for r in cmd.reports:
        reports[r.joint] = (r.position, r.torque_or_force, r.velocity)
    return "joint reports configured"


async def configure_status_report(session, cmd: m.ConfigureStatusReport) -> str:
    r = session.settings.reporting
    r.joints, r.pose, r.gripper = cmd.report_joints, cmd.report_pose, cmd.report_gripper
    r.settings, r.sensors, r.guards = cmd.report_settings, cmd.report_sensors, cmd.report_guards
    return "status report configured"


MAX_DWELL = 86_400.0   # s


async def dwell(session, cmd: m.Dwell) -> str:
    if cmd.seconds > MAX_DWELL:
        raise CrclError(f"a dwell of {cmd.seconds:g} s is longer than a day")
    if cmd.seconds > 0:
        await asyncio.sleep(cmd.seconds)
    return f"dwelled {cmd.seconds:g} s"


async def message(session, cmd: m.Message) -> str:
    # On the device's event stream, where every supervisor (the dashboard) shows it.
    await session.control.robot.post_message(cmd.text)
    return "posted on the device's event stream"


async def loop_block(session, cmd: m.Command) -> str:
    raise CrclError(f"{cmd.KIND} belongs in a CRCLProgram: the program's runner repeats the "
                    f"block; alone it means nothing")


# ---- robot parameters: the device settings no CRCL command sets ----------------------------------

def _pose_values(session, text: str) -> list[float]:
    """x y z roll pitch yaw in the session's units -> SI."""
    try:
        values = pose_values(text)
    except ValueError as error:
        raise CrclError(f"{error} (current length and angle units)") from None
    units = session.settings.units
    return [units.length_si(v) for v in values[:3]] + [units.angle_si(v) for v in values[3:]]


async def _tool_offset(session, value: str) -> None:
    await session.control.set_tool_offset(_pose_values(session, value))


async def _workstation_frame(session, value: str) -> None:
    session.settings.frame = tuple(_pose_values(session, value))


# name -> what it sets; values are "x y z roll pitch yaw" in the session's units. Both last
# until the session ends: the frame is the session's own, the device's tool offset is put back.
ROBOT_PARAMETERS = {
    "ToolOffset": _tool_offset,            # the controlled point in the flange frame
    "WorkstationFrame": _workstation_frame,   # CRCL's frame in the robot's base frame
}


def _known(name: str) -> None:
    if name not in ROBOT_PARAMETERS:
        raise CrclError(f"unknown robot parameter {name!r}; known: {', '.join(ROBOT_PARAMETERS)}")


async def set_robot_parameters(session, cmd: m.SetRobotParameters) -> str:
    for setting in cmd.settings:
        _known(setting.name)
    for setting in cmd.settings:
        await ROBOT_PARAMETERS[setting.name](session, setting.value)
        session.settings.robot_parameters[setting.name] = setting.value
    return f"set {', '.join(s.name for s in cmd.settings)}"


async def enable_parameter_status(session, cmd: m.EnableRobotParameterStatus) -> str:
    _known(cmd.parameter)
    session.settings.reported_parameters.add(cmd.parameter)
    return f"{cmd.parameter} reported in SettingsStatus"


async def disable_parameter_status(session, cmd: m.DisableRobotParameterStatus) -> str:
    _known(cmd.parameter)
    session.settings.reported_parameters.discard(cmd.parameter)
    return f"{cmd.parameter} no longer reported"
