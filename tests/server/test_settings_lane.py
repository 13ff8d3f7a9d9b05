"""The settings' bodies run on the event loop when no other command holds the turn (guard.py
`on_loop`, issue 31 item 2), and still one command at a time: while another command holds the
turn, a Set waits for it on a command thread, and reads go on meanwhile."""
from __future__ import annotations

import threading

import grpc
import pytest

from landscape.v1 import settings_pb2, types_pb2

from support import error_info, locked_session, stubs

SPEED = settings_pb2.SetSpeedRequest(speed=37, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED)


def _speed(device) -> float:
    return device.GetVelocities(settings_pb2.GetVelocitiesRequest(), timeout=5).percent_velocity


def test_a_setting_waits_for_the_command_holding_the_turn(server):
    holder = locked_session(server, "holder")
    device, _, _ = stubs(holder.channel)
    turn = server.device.state_machine.turn
    done = threading.Event()
    try:
        assert turn.acquire(timeout=5)          # a command in progress
        try:
            threading.Thread(target=lambda: (device.SetSpeed(SPEED, timeout=30), done.set()),
                             daemon=True).start()
            for _ in range(20):                 # the loop goes on serving reads meanwhile
                assert _speed(device) != 37
            assert not done.is_set()
        finally:
            turn.release()
        assert done.wait(30)
        assert _speed(device) == 37
    finally:
        holder.close()


def test_a_setting_on_the_loop_is_still_the_lock_holders(server):
    holder = locked_session(server, "holder")
    try:
        with grpc.insecure_channel(server.target) as other:
            device, _, _ = stubs(other)
            with pytest.raises(grpc.RpcError) as refused:
                device.SetSpeed(SPEED, timeout=5)
            assert refused.value.code() is grpc.StatusCode.PERMISSION_DENIED
            assert error_info(refused.value).reason == "NOT_LOCK_HOLDER"
            assert _speed(device) != 37
    finally:
        holder.close()
