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
