"""Issue 10, seed 4.1 sendCommand: the vendor hook's commands on the real server."""
from __future__ import annotations

import grpc
import numpy as np
import pytest

from landscape.sim.recorder import read_recording
from landscape.v1 import end_effector_pb2 as ee

from support import Arm, error_info, stubs


@pytest.fixture
def arm(tmp_path, backend):
    a = Arm(tmp_path, backend=backend)
    yield a
    a.close()


def _send(device, text: str) -> str:
    return device.SendCommand(ee.SendCommandRequest(input=text), timeout=30).result


def _refused(call) -> grpc.RpcError:
    with pytest.raises(grpc.RpcError) as refused:
        call()
    return refused.value


def test_help_version_and_cycle_stats(arm):
    listed = _send(arm.device, "help")
    for command in ("version", "cycle stats", "recorder start", "recorder store", "tare <sensor>"):
        assert command in listed
    assert "landscape-grpc" in _send(arm.device, "version") and "TX90" in _send(arm.device,
                                                                               "version")
    assert "lock-step" in _send(arm.device, "cycle stats")


def test_the_recorder_writes_the_cycles_to_mcap(arm):
    assert _send(arm.device, "recorder start") == "recording"
    arm.move_down_to(0.6, 0.0, 0.6)
    assert _send(arm.device, "recorder stop") == "stopped"
    assert str(arm.record) in _send(arm.device, "recorder store")
    data = read_recording(str(arm.record))
    assert len(data["fbk_pos"]) > 100 and np.ptp(data["fbk_pos"], axis=0).max() > 0.1


@pytest.mark.physics   # the world: tools, parts, wired inputs, sensor readings
def test_tare_zeroes_the_force_sensor(arm):
    arm.get_tool("vacuum")
    assert arm.reading()[2] > 5.0                       # the cup's weight
    assert _send(arm.device, "tare force_sensor") == "force_sensor tared"
    assert np.abs(arm.reading()).max() < 0.01


def test_unknown_commands_list_the_known_ones_and_changes_need_the_lease(arm):
    error = _refused(lambda: _send(arm.device, "reboot"))
    assert error.code() is grpc.StatusCode.INVALID_ARGUMENT
    assert error_info(error).metadata["ret_code"] == "-2" and "recorder start" in error.details()
    error = _refused(lambda: _send(arm.device, "recorder stop"))
    assert error.code() is grpc.StatusCode.FAILED_PRECONDITION     # nothing recorded yet

    other = grpc.insecure_channel(arm.server.target)
    device = stubs(other)[0]
    assert "TX90" in _send(device, "version")                       # reading: anyone
    error = _refused(lambda: _send(device, "tare force_sensor"))
    assert error.code() is grpc.StatusCode.PERMISSION_DENIED
    other.close()
