"""Every CRCL command type, and the function that carries it out (none is silently ignored).

InitCanon, EndCanon and GetStatus belong to the session itself (session.py).
"""
from __future__ import annotations

from landscape.gateway import configure, motions, tooling
from landscape.gateway import model as m

HANDLERS = {
    m.ActuateJoints: motions.actuate_joints,
    m.MoveTo: motions.move_to,
    m.MoveThroughTo: motions.move_through_to,
    m.MoveScrew: motions.move_screw,
    m.StopMotion: motions.stop_motion,
    m.SetAngleUnits: configure.set_units,
    m.SetLengthUnits: configure.set_units,
    m.SetForceUnits: configure.set_units,
    m.SetTorqueUnits: configure.set_units,
    m.SetTransSpeed: configure.set_rate,
    m.SetRotSpeed: configure.set_rate,
    m.SetTransAccel: configure.set_rate,
    m.SetRotAccel: configure.set_rate,
    m.SetEndPoseTolerance: configure.set_end_pose_tolerance,
    m.SetIntermediatePoseTolerance: configure.set_intermediate_pose_tolerance,
    m.SetDefaultJointPositionsTolerances: configure.set_default_joint_tolerances,
    m.SetMotionCoordination: configure.set_motion_coordination,
    m.ConfigureJointReports: configure.configure_joint_reports,
    m.ConfigureStatusReport: configure.configure_status_report,
    m.Dwell: configure.dwell,
    m.Message: configure.message,
    m.SetRobotParameters: configure.set_robot_parameters,
    m.EnableRobotParameterStatus: configure.enable_parameter_status,
    m.DisableRobotParameterStatus: configure.disable_parameter_status,
    m.LoopBlockStart: configure.loop_block,
    m.LoopBlockEnd: configure.loop_block,
    m.CloseToolChanger: tooling.close_tool_changer,
    m.OpenToolChanger: tooling.open_tool_changer,
    m.SetEndEffector: tooling.set_end_effector,
    m.SetEndEffectorParameters: tooling.set_end_effector_parameters,
    m.EnableGripper: tooling.enable_gripper,
    m.DisableGripper: tooling.disable_gripper,
    m.EnableSensor: tooling.enable_sensor,
    m.DisableSensor: tooling.disable_sensor,
    m.RunProgram: tooling.run_program,
}

SESSION_COMMANDS = (m.InitCanon, m.EndCanon, m.GetStatus)

# Commands carried out without the device (settings and reporting): their handlers never
# await anything, so the session runs them at once when it is idle, and they are Done before
# the next document is read (tests/gateway/test_gateway.py checks every one).
IMMEDIATE = frozenset({
    m.SetAngleUnits, m.SetLengthUnits, m.SetForceUnits, m.SetTorqueUnits,
    m.SetTransSpeed, m.SetRotSpeed, m.SetTransAccel, m.SetRotAccel,
    m.SetEndPoseTolerance, m.SetIntermediatePoseTolerance, m.SetDefaultJointPositionsTolerances,
    m.SetMotionCoordination, m.ConfigureJointReports, m.ConfigureStatusReport,
    m.EnableRobotParameterStatus, m.DisableRobotParameterStatus, m.EnableGripper,
    m.DisableGripper})


def immediate(command: m.Command) -> bool:
    """Whether the command is carried out without the device and without waiting (a Dwell of
    no time is a point in a program, nothing to wait for)."""
    return type(command) in IMMEDIATE or (isinstance(command, m.Dwell) and command.seconds == 0)
