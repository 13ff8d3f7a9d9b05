"""Issue 10: the operator panel (DeviceService.OperatePanel), as a person at the cell uses it:
the e-stop pressed during a path cuts the drives in the same controller cycle, the device goes
to Error with an alarm, and Reset is refused until the e-stop is released."""
from __future__ import annotations

import math
import subprocess
import sys
import threading

import grpc
import numpy as np
import pytest

from landscape.server.events import alarms
from landscape.server.cycle.feedback import ENABLE, ESTOP, SEQ
from landscape.server.device.states import State
from landscape.robot.controller import EnableState
from landscape.v1 import control_pb2, motion_pb2, types_pb2
from landscape.v1 import digital_io_service_pb2 as pb

from support import Arm, error_info, stubs, wait_until


@pytest.fixture
def arm(tmp_path, backend):
    a = Arm(tmp_path, pace=1.0, backend=backend)
    yield a
    a.close()


def _panel(channel, action) -> control_pb2.OperatePanelResponse:
    device = stubs(channel)[0]
    return device.OperatePanel(control_pb2.OperatePanelRequest(action=action), timeout=5)


def _path(arm) -> str:
    tags = [types_pb2.TagStruct(x=0.55 + 0.15 * math.cos(a), y=0.15 * math.sin(a), z=0.7,
                                roll=math.pi, tag_name=f"t{i}")
            for i, a in enumerate(np.linspace(0, 2 * math.pi, 9))]
    header = motion_pb2.PathHeader(path_name="circle",
                                   frame=types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME,
                                   motion_type=types_pb2.MOTION_TYPE_STRAIGHT_MOTION,
                                   offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)
    arm.device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header, tags=tags)]), timeout=30)
    return arm.device.PathMove(motion_pb2.PathMoveRequest(path_name="circle"),
                               timeout=10).ret_val.command_id


def test_the_estop_during_a_path_cuts_the_drives_in_the_same_cycle(arm):
    command_id = _path(arm)
    wait_until(lambda: np.abs(arm.server.device.feedback().velocity).max() > 0.05, timeout=10)
    before = arm.server.link.feedback.head
    # Anyone at the cell presses it: a client that holds no lease.
    bystander = grpc.insecure_channel(arm.server.target)
    reply = _panel(bystander, control_pb2.PANEL_ACTION_PRESS_ESTOP)
    assert reply.estop_pressed and not reply.door_open

    wait_until(lambda: arm.server.device.state is State.ERROR, timeout=5)
    ring = arm.server.link.feedback
    rows = np.array([ring.row(s) for s in range(before, ring.head + 1)])
    pressed = np.nonzero(rows[:, ESTOP] == 1.0)[0]
    first = rows[pressed[0]]
    print(f"\ne-stop seen in cycle {int(first[SEQ])}: enable state {EnableState(int(first[ENABLE])).name}")
    assert rows[pressed[0] - 1, ENABLE] == EnableState.ENABLED       # moving until then
    assert np.all(rows[pressed, ENABLE] == EnableState.DISABLED)     # cut in that very cycle
    wait_until(lambda: np.abs(arm.server.device.feedback().velocity).max() < 1e-3, timeout=5)

    events = arm.wait_command(command_id)
    assert events[-1].event_id == "command_failed"
    alarm = next(e.detail for e in arm.history()
                 if e.event_id == "alarm" and e.detail.code == alarms.ESTOP)
    assert alarm.severity.name == "CRITICAL"

    with pytest.raises(grpc.RpcError) as refused:
        arm.device.Reset(control_pb2.ResetRequest(), timeout=5)
    assert error_info(refused.value).reason == "ESTOP_ACTIVE"
    assert arm.server.device.state is State.ERROR

    reply = _panel(bystander, control_pb2.PANEL_ACTION_RELEASE_ESTOP)
    assert not reply.estop_pressed
    reset = arm.device.Reset(control_pb2.ResetRequest(), timeout=5)
    assert reset.state == types_pb2.DEVICE_STATE_INACTIVE          # the holder keeps the lock
    bystander.close()


def test_the_door_is_an_input_of_the_cell(arm):
    io = stubs(arm.session.channel)[1]
    safety = lambda: io.GetDigitalIO(pb.GetDigitalIORequest(type="input", unit_id=0)).bits_on  # noqa: E731
    assert safety() == 1 << 1                                       # door closed
    assert _panel(arm.session.channel, control_pb2.PANEL_ACTION_OPEN_DOOR).door_open
    assert safety() == 0
    _panel(arm.session.channel, control_pb2.PANEL_ACTION_CLOSE_DOOR)
    assert safety() == 1 << 1
    assert arm.server.device.state is State.RESTING                 # the supervisor's policy


def test_the_panel_has_a_lane_of_its_own(arm):
    """Every thread that serves slow reads is busy (here: held); the e-stop still goes in."""
    held = threading.Event()
    busy = [arm.server.dispatch.reads.submit(held.wait, 10) for _ in range(8)]
    try:
        reply = _panel(arm.session.channel, control_pb2.PANEL_ACTION_PRESS_ESTOP)
        assert reply.estop_pressed
        wait_until(lambda: arm.server.device.state is State.ERROR)
    finally:
        held.set()
    assert all(f.result(5) for f in busy)


def test_the_device_server_does_not_import_the_physics():
    """DESIGN.md 7: nothing above the controller interface imports pybullet (the panel's
    helper, which the server hands to the cycle, lives beside the panel without it)."""
    code = "import sys, landscape.server.app; sys.exit('pybullet' in sys.modules)"
    assert subprocess.run([sys.executable, "-c", code], timeout=60).returncode == 0
