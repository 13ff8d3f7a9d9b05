"""Every RPC against every state the device can be put in: valid calls are accepted, the others
fail with FAILED_PRECONDITION and the seed's return code, and change nothing (DESIGN.md 4)."""
from __future__ import annotations

import grpc
import pytest
from google.protobuf import message_factory

from landscape.server.api import services
from landscape.server.device.states import State
from landscape.v1 import device_service_pb2_grpc, motion_pb2, settings_pb2, types_pb2

from support import activate, error_info, locked_session, start_server, wait_until

# A request each RPC accepts when its state allows it (the rest: the default message).
VALID_REQUESTS = {
    "SetSpeed": settings_pb2.SetSpeedRequest(speed=10, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED),
    "SetAcceleration": settings_pb2.SetAccelerationRequest(
        accel=10, attribute=types_pb2.ACCEL_TYPE_PERCENT_ACCEL),
    "SetUnits": settings_pb2.SetUnitsRequest(linear_units=types_pb2.LINEAR_UNIT_METERS,
                                             angular_units=types_pb2.ANGULAR_UNIT_RADIANS),
}

METHODS = [(spec, m) for spec in services.ALL for m in spec.descriptor.methods]

# Where each RPC is valid, written from the seed's section headings (SAND98-2770 3.1 to 4)
# and DESIGN.md section 4, independently of the server's own table. As DESIGN.md 4 reads them,
# "Locked" is holding the lock (Inactive and the Active states) and "Active" is Resting, Moving
# or Paused; "state neutral" / "state independent" is every state. Where an entry departs from
# the seed's words, its comment says "seed:" and why; the others are the seed's own.
ALL = set(State)
LOCKED = {State.INACTIVE, State.RESTING, State.MOVING, State.PAUSED}
ACTIVE = {State.RESTING, State.MOVING, State.PAUSED}
READS = ["GetUnits", "GetVelocities", "GetAccelerations", "GetMaxVelocities",
         "GetMaxAccelerations", "GetToolOffsets", "GetRobotPosition", "GetMotionControlState",
         "GetTagId",                                              # 3.3.1 state neutral
         "GetWorldCartesianFrame",                                # 3.3.1's, for 3.2.1's set
         "GetSensorReading",                                      # 3.7.1 state independent
         "GetEndEffectorState",                                   # 3.8.1 state independent
         "GetDigitalIO", "SignalDigitalIO", "SendCommand",        # 4.1 state independent
         "Subscribe", "Connect",                                  # 2.1, 2.2 state independent
         # Extensions, read-only (OperatePanel is the person at the cell: no lease, any state).
         "GetDeviceState", "GetRobotDescription", "GetCellDescription", "OperatePanel",
         "ListDigitalIO", "StreamState",
         "FetchRecording",                 # the recorder's stored file (LLI s7.4 5.5)
         "ListPaths", "GetPath",           # the stored paths (3.5.1) read back
         "AcknowledgeAlarm",               # 2.1's alarms, acknowledged: an operator's, no lease
         "SolvePose",                      # 3.4.1's planning, nothing moves
         "ReadAuditLog",                   # the audit log: an admin's
         ]
# The seed's headings put every motion command in "Active" (3.4.1, 3.5.2) but its text for
# moveReact (3.7.2) says "valid only in the Resting State": one motion at a time, so a command
# that starts a motion needs the arm at rest (DESIGN.md 4: Resting --move--> Moving).
STARTS_A_MOTION = {State.RESTING}
EXPECTED = {
    **{rpc: ALL for rpc in READS},
    "Lock": {State.UNLOCKED},                                   # 3.1.1
    # 3.1.2 seed: "Locked". Not while Active: handing LOCAL control over (release) with the
    # drives on, or activating what is active, has no meaning; DESIGN.md 4 draws both from
    # Inactive. Release in Error too: a holder may give up control rather than reset.
    "Release": {State.INACTIVE, State.ERROR},
    "Activate": {State.INACTIVE},
    "Deactivate": ACTIVE,                                       # 3.1.3
    **{rpc: LOCKED for rpc in ("SetSpeed", "SetAcceleration", "SetToolOffset",
                               "SetWorldCartesianFrame", "SetUnits")},
    # 3.2.1; setUnits is named there (never defined): a set command like the others.
    # 3.4.1 seed: "Active": see STARTS_A_MOTION.
    **{rpc: STARTS_A_MOTION for rpc in ("MoveRelative", "MoveAbsolute", "MoveArc")},
    "PathLoad": LOCKED, "PathClearPath": LOCKED,                # 3.5.1 "Locked or Resting"
    "PathMove": STARTS_A_MOTION,                                # 3.5.2 seed: "Active"
    "StopMotion": {State.MOVING},                               # 3.6.1
    # 3.6.2 seed: "Paused or Locked", the heading it shares with abortMotion. Resume continues
    # the motion stopMotion paused; in any other state there is none (it ended, or Deactivate
    # or abortMotion ended it), and accepting a resume of nothing would leave the client
    # waiting for a done event that never comes.
    "ResumeMotion": {State.PAUSED},
    # 3.6.2 seed: "Paused or Locked". Not Moving: it "aborts current motion stopped by
    # stopMotion()", so a moving arm is stopped first (StopMotion never waits, Deactivate
    # stops it too).
    "AbortMotion": {State.INACTIVE, State.RESTING, State.PAUSED},
    "MoveReact": {State.RESTING},                               # 3.7.2 "Resting"
    "Comply": {State.RESTING, State.MOVING},                    # 3.7.2 "Resting and Moving"
    # 3.7.3 seed: "Locked". Not Moving or Paused: the teach pendant or spaceball would take an
    # arm in the middle of a programmed motion; that motion ends (or is aborted) first.
    "ManualControl": {State.INACTIVE, State.RESTING},
    "Jog": {State.RESTING},             # extension: manual control's motion (STARTS_A_MOTION)
    # 3.8.1 seed: "state independent". Picking and putting away a tool moves the arm
    # (DESIGN.md 4): STARTS_A_MOTION.
    "GetTool": STARTS_A_MOTION, "PutTool": STARTS_A_MOTION,
    # 3.8.1 and 4.1 seed: "state independent", read as "whatever the motion state": these
    # change the cell (the tool, its outputs), so only the lock holder may (3.1.1: the lock
    # gives exclusive control), and not in Error, where the e-stop or fault holds the cell as
    # it is until Reset. Every state the holder is in but Error: LOCKED.
    "ActivateTool": LOCKED, "DeactivateTool": LOCKED, "SetDigitalIO": LOCKED,
    "Reset": {State.ERROR},             # extension: leaving Error once its cause is cleared
    "PostMessage": ALL,                 # 2.1 clientEvent's counterpart: state independent
}
# A joint move slow enough to last the whole sweep of a state (about a minute at real time).
SLOW_MOVE = motion_pb2.MoveAbsoluteRequest(frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME,
                                           values=[3.0, 0, 1.5708, 0, 1.5708, 0], speed=1)


def test_the_expected_table_covers_the_whole_contract():
    assert set(EXPECTED) == {method.name for _, method in METHODS}


class Cell:
    """A fresh server brought to `state`, with a session holding the lock where there is one."""

    def __init__(self, state: State):
        self.state = state
        moving = state in (State.MOVING, State.PAUSED)
        self.server = start_server(start_device=state is not State.IDLE,
                                   lockstep_pace=1.0 if moving else None)
        self.session = None
        if state not in (State.IDLE, State.UNLOCKED):
            self.session = locked_session(self.server)
        if state in (State.RESTING, State.MOVING, State.PAUSED):
            activate(self.session)
        if moving:
            device = device_service_pb2_grpc.DeviceServiceStub(self.session.channel)
            device.MoveAbsolute(SLOW_MOVE, timeout=5)
            if state is State.PAUSED:
                device.StopMotion(motion_pb2.StopMotionRequest(), timeout=10)
        if state is State.ERROR:
            self.server.link.between_cycles(lambda c: c.panel.press_estop())
            wait_until(lambda: self.server.device.state is State.ERROR)
        assert self.server.device.state is state

    def close(self):
        if self.session:
            self.session.close()
        self.server.stop(grace=None)

    def call(self, spec, method):
        channel = self.session.channel if self.session else grpc.insecure_channel(self.server.target)
        request = VALID_REQUESTS.get(method.name)
        if request is None:
            request = message_factory.GetMessageClass(method.input_type)()
        if method.name == "Lock":
            owner = self.session or _Opened(self.server).session
            request.session_id, request.session_secret = owner.session_id, owner.session_secret
        if method.name == "Connect":
            request.hello.client_name = "table"
        stub = getattr(spec.grpc, f"{spec.name}Stub")(channel)
        rpc = getattr(stub, method.name)
        arg = iter([request]) if method.client_streaming else request
        if method.server_streaming:
            return next(rpc(arg, timeout=0.3))
        return rpc(arg, timeout=5)


class _Opened:
    """A session for Lock in states where the cell holds none (it stays open until the end)."""

    def __init__(self, server):
        from landscape.client import Session
        self.session = Session(grpc.insecure_channel(server.target), "locker").open()
        self.session_id = self.session.session_id


@pytest.mark.parametrize("state", list(State), ids=lambda s: s.value)
def test_every_rpc_in_state(state):
    cell = Cell(state)
    try:
        for spec, method in METHODS:
            valid = EXPECTED[method.name]
            before = (cell.server.device.state, cell.server.device.settings,
                      cell.server.device.status().lock_holder)
            refused = False
            try:
                cell.call(spec, method)
            except grpc.RpcError as error:
                if error.code() is grpc.StatusCode.FAILED_PRECONDITION:
                    info = error_info(error)
                    refused = info.reason == "WRONG_STATE"
                    assert not refused or info.metadata["ret_code"] == "-1"
            except StopIteration:
                pass
            if state in valid:
                assert not refused, method.full_name
            else:
                assert refused, method.full_name
                after = (cell.server.device.state, cell.server.device.settings,
                         cell.server.device.status().lock_holder)
                assert after[0] is before[0] and after[1] is before[1] and after[2] == before[2]
            if cell.server.device.state is not state:  # a valid call moved it: start again
                cell.close()
                cell = Cell(state)
    finally:
        cell.close()
