"""The device's states and, for every RPC, where it is valid: DESIGN.md section 4 as one table.

Seed sections name the states of each command (SAND98-2770, section 3); "Locked" reads as
"holding the lock", which Inactive and the Active states (Resting, Moving, Paused) all do. A
call outside its states changes nothing and fails with FAILED_PRECONDITION; a call that needs
the lease fails with PERMISSION_DENIED for anyone but the lock holder.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass


class State(enum.Enum):
    IDLE = "idle"            # booted; controller not initialised/homed yet
    UNLOCKED = "unlocked"
    INACTIVE = "inactive"    # locked, drives off
    RESTING = "resting"      # locked, active, no motion
    MOVING = "moving"
    PAUSED = "paused"        # a motion stopped by StopMotion, resumable
    ERROR = "error"          # e-stop or fault: drives off until Reset


ALL = frozenset(State)
LOCKED = frozenset({State.INACTIVE, State.RESTING, State.MOVING, State.PAUSED})
ACTIVE = frozenset({State.RESTING, State.MOVING, State.PAUSED})
RESTING = frozenset({State.RESTING})


class Lease(enum.Enum):
    NONE = "none"            # read-only: every client
    SESSION = "session"      # Lock: any client with an open session
    HOLDER = "holder"        # mutating: the lock holder only
    HOLDER_IF_LOCKED = "holder_if_locked"  # the holder if any, else any client (Reset)


@dataclass(frozen=True)
class Rule:
    states: frozenset
    lease: Lease
    seed: str                # the seed section that names the states
    # Stops the arm: never waits behind another command (DESIGN.md 5).
    immediate: bool = False


def _read(seed: str) -> Rule:
    return Rule(ALL, Lease.NONE, seed)


def _cmd(states, seed: str, immediate: bool = False) -> Rule:
    return Rule(frozenset(states), Lease.HOLDER, seed, immediate)


RULES: dict[str, Rule] = {
    # 3.1 connect / power / single point of control
    "Lock": Rule(frozenset({State.UNLOCKED}), Lease.SESSION, "3.1.1"),
    # Release only with the drives off (Inactive), or to give up control in Error.
    "Release": _cmd({State.INACTIVE, State.ERROR}, "3.1.2"),
    "Activate": _cmd({State.INACTIVE}, "3.1.2"),
    "Deactivate": _cmd(ACTIVE, "3.1.3", immediate=True),
    # 3.2 set commands: any locked state; they apply to later motions
    "SetSpeed": _cmd(LOCKED, "3.2.1"),
    "SetAcceleration": _cmd(LOCKED, "3.2.1"),
    "SetToolOffset": _cmd(LOCKED, "3.2.1"),
    "SetWorldCartesianFrame": _cmd(LOCKED, "3.2.1"),
    "SetUnits": _cmd(LOCKED, "3.2"),
    # 3.3 get commands: state neutral
    "GetUnits": _read("3.3.1"),
    "GetVelocities": _read("3.3.1"),
    "GetAccelerations": _read("3.3.1"),
    "GetMaxVelocities": _read("3.3.1"),
    "GetMaxAccelerations": _read("3.3.1"),
    "GetToolOffsets": _read("3.3.1"),
    "GetWorldCartesianFrame": _read("3.3.1"),
    "GetRobotPosition": _read("3.3.1"),
    "GetMotionControlState": _read("3.3.1"),
    "GetTagId": _read("3.3.1"),
    # 3.4 single motions: Active and at rest
    "MoveRelative": _cmd(RESTING, "3.4.1"),
    "MoveAbsolute": _cmd(RESTING, "3.4.1"),
    "MoveArc": _cmd(RESTING, "3.4.1"),
    # 3.5 paths
    "PathLoad": _cmd(LOCKED, "3.5.1"),
    "PathClearPath": _cmd(LOCKED, "3.5.1"),
    "PathMove": _cmd(RESTING, "3.5.2"),
    # 3.6 interruptions
    "StopMotion": _cmd({State.MOVING}, "3.6.1", immediate=True),
    "ResumeMotion": _cmd({State.PAUSED}, "3.6.2"),
    "AbortMotion": _cmd({State.INACTIVE, State.RESTING, State.PAUSED}, "3.6.2", immediate=True),
    # 3.7 sensors
    "GetSensorReading": _read("3.7.1"),
    "MoveReact": _cmd(RESTING, "3.7.2"),
    "Comply": _cmd({State.RESTING, State.MOVING}, "3.7.2"),
    "ManualControl": _cmd({State.INACTIVE, State.RESTING}, "3.7.3"),
    "Jog": _cmd(RESTING, "3.7.3"),
    # 3.8 end effector: state independent, but picking and placing tools moves the arm
    "GetEndEffectorState": _read("3.8.1"),
    "GetTool": _cmd(RESTING, "3.8.1"),
    "PutTool": _cmd(RESTING, "3.8.1"),
    "ActivateTool": _cmd(LOCKED, "3.8.1"),
    "DeactivateTool": _cmd(LOCKED, "3.8.1"),
    "SendCommand": _read("4.1"),
    # extensions
    "Reset": Rule(frozenset({State.ERROR}), Lease.HOLDER_IF_LOCKED, "-"),
    "GetDeviceState": _read("-"),
    "GetRobotDescription": _read("-"),
    "GetCellDescription": _read("-"),
    # stored paths read back
    "ListPaths": _read("3.5.1"),
    "GetPath": _read("3.5.1"),
    # plan-only: MoveAbsolute's planning and checks, nothing started
    "SolvePose": _read("3.4.1"),
    # The operator panel: no lease (the e-stop works whoever holds the lock); admin only.
    "OperatePanel": _read("-"),
    # 4 DIGITAL_IO
    "SetDigitalIO": _cmd(LOCKED, "4.1"),
    "GetDigitalIO": _read("4.1"),
    "SignalDigitalIO": _read("4.1"),
    "ListDigitalIO": _read("4.1"),
    # 2 client IDL
    "Subscribe": _read("2.1"),
    "PostMessage": _cmd(ALL, "2.1"),
    # an operator's, without the lease (auth.py); recorded in the audit
    "AcknowledgeAlarm": _read("2.1"),
    "Connect": _read("2.2"),
    # live state
    "StreamState": _read("-"),
    # the controller recorder's stored file (LLI s7.4 5.5), read-only
    "FetchRecording": _read("-"),
    # the audit log, read back: admin only (auth.py)
    "ReadAuditLog": _read("-"),
}


# getMotionControlState's suggested strings (seed 3.3.1).
RUNNING_TRAJECTORY = "running_trajectory"
ROBOT_PAUSED = "robot_paused"
ROBOT_STOPPED_ON_ERROR = "robot_stopped_on_error"
ROBOT_STOPPED_ON_COMMAND = "robot_stopped_on_command"
ROBOT_IDLE = "robot_idle"
POWER_ON, POWER_OFF, CONTROLLER_ERROR = "power_on", "power_off", "controller_error"
