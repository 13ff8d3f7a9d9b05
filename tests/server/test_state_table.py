"""Every RPC against every state the device can be put in: valid calls are accepted, the others
fail with FAILED_PRECONDITION and the seed's return code, and change nothing (DESIGN.md 4)."""
from __future__ import annotations

import grpc
import pytest
from google.protobuf import message_factory

from landscape.server import services
from landscape.server.states import State
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

# Where each RPC is valid, written from the seed's sections (SAND98-2770 3.1 to 4) and
# DESIGN.md section 4, independently of the server's own table: "Locked" is holding the lock
# (Inactive and the Active states), "Active" is Resting, Moving or Paused; commands that move
# the arm need Resting; read-only and state-neutral calls are valid everywhere.
ALL = set(State)
LOCKED = {State.INACTIVE, State.RESTING, State.MOVING, State.PAUSED}
ACTIVE = {State.RESTING, State.MOVING, State.PAUSED}
READS = ["GetUnits", "GetVelocities", "GetAccelerations", "GetMaxVelocities",
         "GetMaxAccelerations", "GetToolOffsets", "GetRobotPosition", "GetMotionControlState",
         "GetTagId", "GetSensorReading", "GetEndEffectorState", "SendCommand", "GetDeviceState",
         "GetRobotDescription", "GetCellDescription", "OperatePanel", "GetDigitalIO",
         "SignalDigitalIO", "ListDigitalIO", "Subscribe", "Connect", "StreamState"]
EXPECTED = {
    **{rpc: ALL for rpc in READS},
    "Lock": {State.UNLOCKED},                                   # 3.1.1
    "Release": {State.INACTIVE, State.ERROR},                   # 3.1.2 (and giving up an error)
    "Activate": {State.INACTIVE},                               # 3.1.2
    "Deactivate": ACTIVE,                                       # 3.1.3
    **{rpc: LOCKED for rpc in ("SetSpeed", "SetAcceleration", "SetToolOffset",
                               "SetWorldCartesianFrame", "SetUnits")},   # 3.2.1
    **{rpc: {State.RESTING} for rpc in ("MoveRelative", "MoveAbsolute", "MoveArc")},  # 3.4.1
    "PathLoad": LOCKED, "PathClearPath": LOCKED,                # 3.5.1
    "PathMove": {State.RESTING},                                # 3.5.2
    "StopMotion": {State.MOVING},                               # 3.6.1
    "ResumeMotion": {State.PAUSED},                             # 3.6.2
    "AbortMotion": {State.INACTIVE, State.RESTING, State.PAUSED},   # 3.6.2
    "MoveReact": {State.RESTING},                               # 3.7.2
    "Comply": {State.RESTING, State.MOVING},                    # 3.7.2
    "ManualControl": {State.INACTIVE, State.RESTING},           # 3.7.3
    "Jog": {State.RESTING},
    "GetTool": {State.RESTING}, "PutTool": {State.RESTING},     # 3.8.1: they move the arm
    "ActivateTool": LOCKED, "DeactivateTool": LOCKED,           # 3.8.1
    "SetDigitalIO": LOCKED,                                     # 4.1
    "Reset": {State.ERROR},
    "PostMessage": ALL,
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
