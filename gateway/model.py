"""CRCL as typed values: the data primitives and every command of CRCLCommands.xsd (2021).

Written from ../shared/spec/crcl.md section VII and the schemas' structure; one dataclass per
schema type, fields in schema order. Numbers are as sent, in the session's units at the time
the command runs (length, angle, force, torque: see units.py); times are seconds. Optional
schema elements are None when absent. `name` is the optional Name of every DataThingType.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar


from landscape.gateway.primitives import (  # noqa: F401 - part of the model
    Point,
    Vector,
    Rate,
    PoseTolerance,
    PoseSettings,
    Pose,
    ParameterSetting,
    JointTolerance,
    Guard,
    JointSpeedAccel,
    JointForceTorque,
    ActuateJoint,
    JointReport)


# ---- commands (CRCLCommands.xsd) ------------------------------------------------------------------

@dataclass(frozen=True, kw_only=True)
class Command:
    """CRCLCommandType: every command has the client's CommandID; guards end it early."""

    KIND: ClassVar[str] = ""
    MOTION: ClassVar[bool] = False      # moves the arm
    LASTS: ClassVar[bool] = False       # runs for a while: the next command preempts it

    command_id: int
    name: str | None = None
    guards: tuple[Guard, ...] = ()


def _command(kind: str, motion: bool = False):
    def register(cls):
        cls.KIND, cls.MOTION = kind, motion
        cls.LASTS = cls.LASTS or motion
        COMMAND_TYPES[kind + "Type"] = cls
        return cls
    return register


COMMAND_TYPES: dict[str, type] = {}   # xsi:type name -> class


@_command("InitCanon")
@dataclass(frozen=True, kw_only=True)
class InitCanon(Command):
    pass


@_command("EndCanon")
@dataclass(frozen=True, kw_only=True)
class EndCanon(Command):
    pass


@_command("GetStatus")
@dataclass(frozen=True, kw_only=True)
class GetStatus(Command):
    pass


@_command("ActuateJoints", motion=True)
@dataclass(frozen=True, kw_only=True)
class ActuateJoints(Command):
    joints: tuple[ActuateJoint, ...]
    tolerances: tuple[JointTolerance, ...] | None = None


@_command("CloseToolChanger", motion=True)   # the device's tool change moves the arm
@dataclass(frozen=True, kw_only=True)
class CloseToolChanger(Command):
    pass


@_command("OpenToolChanger", motion=True)
@dataclass(frozen=True, kw_only=True)
class OpenToolChanger(Command):
    pass


@_command("ConfigureJointReports")
@dataclass(frozen=True, kw_only=True)
class ConfigureJointReports(Command):
    reset_all: bool
    reports: tuple[JointReport, ...] = ()


@_command("ConfigureStatusReport")
@dataclass(frozen=True, kw_only=True)
class ConfigureStatusReport(Command):
    report_joints: bool
    report_pose: bool
    report_gripper: bool
    report_settings: bool
    report_sensors: bool
    report_guards: bool


@_command("Dwell")
@dataclass(frozen=True, kw_only=True)
class Dwell(Command):
    LASTS: ClassVar[bool] = True
    seconds: float


@_command("Message")
@dataclass(frozen=True, kw_only=True)
class Message(Command):
    text: str


@_command("MoveScrew", motion=True)
@dataclass(frozen=True, kw_only=True)
class MoveScrew(Command):
    axial_distance_screw: float            # length units, + away from the end effector
    turn: float                            # angle units, + counterclockwise seen from +Z
    start: Pose | None = None
    axis_point: Point | None = None
    axial_distance_free: float | None = None


@_command("MoveThroughTo", motion=True)
@dataclass(frozen=True, kw_only=True)
class MoveThroughTo(Command):
    straight: bool
    waypoints: tuple[Pose, ...]
    num_positions: int


@_command("MoveTo", motion=True)
@dataclass(frozen=True, kw_only=True)
class MoveTo(Command):
    straight: bool
    end: Pose


@_command("RunProgram")
@dataclass(frozen=True, kw_only=True)
class RunProgram(Command):
    text: str


@dataclass(frozen=True, kw_only=True)
class SetUnits(Command):
    """The four Set*Units commands: `unit` is one of the schema's names for its quantity."""

    QUANTITY: ClassVar[str] = ""
    unit: str


@_command("SetAngleUnits")
@dataclass(frozen=True, kw_only=True)
class SetAngleUnits(SetUnits):
    QUANTITY: ClassVar[str] = "angle"


@_command("SetLengthUnits")
@dataclass(frozen=True, kw_only=True)
class SetLengthUnits(SetUnits):
    QUANTITY: ClassVar[str] = "length"


@_command("SetForceUnits")
@dataclass(frozen=True, kw_only=True)
class SetForceUnits(SetUnits):
    QUANTITY: ClassVar[str] = "force"


@_command("SetTorqueUnits")
@dataclass(frozen=True, kw_only=True)
class SetTorqueUnits(SetUnits):
    QUANTITY: ClassVar[str] = "torque"


@_command("SetEndEffectorParameters")
@dataclass(frozen=True, kw_only=True)
class SetEndEffectorParameters(Command):
    settings: tuple[ParameterSetting, ...]


@_command("SetEndEffector")
@dataclass(frozen=True, kw_only=True)
class SetEndEffector(Command):
    setting: float                         # 0 closed / off .. 1 fully open / on


@_command("SetEndPoseTolerance")
@dataclass(frozen=True, kw_only=True)
class SetEndPoseTolerance(Command):
    tolerance: PoseTolerance


@_command("SetIntermediatePoseTolerance")
@dataclass(frozen=True, kw_only=True)
class SetIntermediatePoseTolerance(Command):
    tolerance: PoseTolerance


# The schema spells the type "SetDefaultJointPositonsTolerancesType" (sic).
@_command("SetDefaultJointPositonsTolerances")
@dataclass(frozen=True, kw_only=True)
class SetDefaultJointPositionsTolerances(Command):
    tolerances: tuple[JointTolerance, ...]


@_command("SetMotionCoordination")
@dataclass(frozen=True, kw_only=True)
class SetMotionCoordination(Command):
    coordinated: bool


@_command("SetRobotParameters")
@dataclass(frozen=True, kw_only=True)
class SetRobotParameters(Command):
    settings: tuple[ParameterSetting, ...]


@dataclass(frozen=True, kw_only=True)
class SetRate(Command):
    """The four Set{Trans,Rot}{Speed,Accel} commands."""

    QUANTITY: ClassVar[str] = ""
    rate: Rate


@_command("SetTransSpeed")
@dataclass(frozen=True, kw_only=True)
class SetTransSpeed(SetRate):
    QUANTITY: ClassVar[str] = "TransSpeed"


@_command("SetRotSpeed")
@dataclass(frozen=True, kw_only=True)
class SetRotSpeed(SetRate):
    QUANTITY: ClassVar[str] = "RotSpeed"


@_command("SetTransAccel")
@dataclass(frozen=True, kw_only=True)
class SetTransAccel(SetRate):
    QUANTITY: ClassVar[str] = "TransAccel"


@_command("SetRotAccel")
@dataclass(frozen=True, kw_only=True)
class SetRotAccel(SetRate):
    QUANTITY: ClassVar[str] = "RotAccel"


@_command("StopMotion")
@dataclass(frozen=True, kw_only=True)
class StopMotion(Command):
    condition: str                         # Immediate, Fast or Normal


@_command("EnableSensor")
@dataclass(frozen=True, kw_only=True)
class EnableSensor(Command):
    sensor_id: str
    options: tuple[ParameterSetting, ...] = ()


@_command("DisableSensor")
@dataclass(frozen=True, kw_only=True)
class DisableSensor(Command):
    sensor_id: str


@_command("EnableGripper")
@dataclass(frozen=True, kw_only=True)
class EnableGripper(Command):
    gripper_name: str
    options: tuple[ParameterSetting, ...] = ()


@_command("DisableGripper")
@dataclass(frozen=True, kw_only=True)
class DisableGripper(Command):
    gripper_name: str


@_command("EnableRobotParameterStatus")
@dataclass(frozen=True, kw_only=True)
class EnableRobotParameterStatus(Command):
    parameter: str


@_command("DisableRobotParameterStatus")
@dataclass(frozen=True, kw_only=True)
class DisableRobotParameterStatus(Command):
    parameter: str


@_command("LoopBlockStart")
@dataclass(frozen=True, kw_only=True)
class LoopBlockStart(Command):
    loop_name: str


@_command("LoopBlockEnd")
@dataclass(frozen=True, kw_only=True)
class LoopBlockEnd(Command):
    loop_name: str
    max_count: int


# ---- documents -------------------------------------------------------------------------------------

@dataclass(frozen=True)
class CommandInstance:
    """CRCLCommandInstance: one command, and where it sits in a program if the sender says."""

    command: Command
    program_file: str | None = None
    program_index: int | None = None
    program_length: int | None = None


@dataclass(frozen=True)
class Program:
    """CRCLProgram: InitCanon, the middle commands in order, EndCanon."""

    commands: tuple[Command, ...]
    name: str | None = None
