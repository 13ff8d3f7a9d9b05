"""Issue 9: what a newcomer meets first: start-up errors in one line, replies and refusals that
say what happened, sessions that end with a reason, nothing unexpected escaping as UNKNOWN."""
from __future__ import annotations

import socket
import subprocess
import sys
import time

import grpc
import pytest

from landscape.client import Session
from landscape.v1 import control_pb2, digital_io_service_pb2, settings_pb2, types_pb2

from support import error_info, locked_session, start_server, stubs, wait_until

SERVER = [sys.executable, "-m", "landscape.server", "--clock", "lockstep"]


def _start(*args, timeout=30):
    return subprocess.run([*SERVER, *args], capture_output=True, text=True, timeout=timeout)


def _refusal(*args) -> str:
    """The one line a server that cannot listen writes, checking that it exits 2 without a
    traceback and before it loads the simulation (-X importtime: no sim module imported)."""
    began = time.monotonic()
    done = subprocess.run([sys.executable, "-X", "importtime", *SERVER[1:], *args],
                          capture_output=True, text=True, timeout=60)
    took = time.monotonic() - began
    imported = [line.rsplit("|", 1)[-1].strip() for line in done.stderr.splitlines()
                if line.startswith("import time:")]
    lines = [line for line in done.stderr.splitlines()
             if line.strip() and not line.startswith("import time:")]
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert "Traceback" not in done.stderr
    assert not [m for m in imported if m.startswith(("landscape.sim", "pybullet"))], imported
    print(f"refused in {took:.2f} s: {lines[0]}")
    return lines[0]


def test_a_port_in_use_is_one_line_naming_the_cause_and_exits_non_zero(tmp_path):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        line = _refusal("--port", str(port), "--paths", str(tmp_path / "p.db"))
    assert line.startswith(f"landscape-device-server: cannot listen on 127.0.0.1:{port}: "
                           f"port {port} is in use"), line
    assert "--port" in line


def test_an_address_not_of_this_machine_is_told_apart_from_a_port_in_use(tmp_path):
    """192.0.2.1 is TEST-NET-1 (RFC 5737): no machine's own address."""
    line = _refusal("--address", "192.0.2.1", "--insecure", "--port", "0",
                    "--paths", str(tmp_path / "p.db"))
    assert "192.0.2.1 is not an address of this machine" in line and "--address" in line, line
    assert "in use" not in line


def test_an_ipv6_address_works_with_or_without_brackets(tmp_path):
    if not socket.has_ipv6:
        pytest.skip("this machine has no IPv6")
    for address in ("::1", "[::1]"):
        proc = subprocess.Popen([*SERVER, "--address", address, "--port", "0",
                                 "--paths", str(tmp_path / "p.db")],
                                stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            line = proc.stdout.readline()
            if "listening on" not in line:
                error = proc.stderr.read()
                if "cannot listen" in error:
                    pytest.skip(f"no IPv6 loopback here: {error.strip()}")
                raise AssertionError(error)
            target = line.split()[-1]
            assert target.startswith("[::1]:")
            with grpc.insecure_channel(target) as channel:
                stub, _, _ = stubs(channel)
                assert stub.GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=10)
        finally:
            proc.terminate()
            assert proc.wait(timeout=20) == 0


def test_lock_held_by_another_names_the_holder(server):
    holder = locked_session(server, "first-operator")
    try:
        with grpc.insecure_channel(server.target) as channel:
            other = Session(channel, "second").open()
            with pytest.raises(grpc.RpcError) as refused:
                other.lock()
            assert refused.value.code() is grpc.StatusCode.FAILED_PRECONDITION
            assert "first-operator" in refused.value.details()
            assert error_info(refused.value).metadata["holder"] == "first-operator"
            other.close()
    finally:
        holder.close()


def test_a_session_the_server_ends_closes_with_its_reason(server):
    registry = server.device.sessions
    registry.keepalive_timeout = 0.3
    with grpc.insecure_channel(server.target) as channel:
        session = Session(channel, "quiet").open()
        session._interval = 3600   # it stops sending keep-alives
        wait_until(lambda: session._closed.is_set(), timeout=5)
        assert session.end_status is grpc.StatusCode.DEADLINE_EXCEEDED
        assert "keep-alive" in session.end_details


def test_a_session_the_server_shutdown_ends_is_told_so():
    """The lock holder's session too: its stream ends UNAVAILABLE saying the server stops, so a
    client knows to reconnect later rather than that it did something wrong."""
    server = start_server()
    stopped = False
    try:
        holder = locked_session(server, "holder")
        with grpc.insecure_channel(server.target) as channel:
            watcher = Session(channel, "watcher").open()
            server.stop()
            stopped = True
            for session in (holder, watcher):
                wait_until(lambda: session._closed.is_set(), timeout=10)
                assert session.end_status is grpc.StatusCode.UNAVAILABLE, session.end_status
                assert session.end_details == "the server is stopping"
        holder.channel.close()
    finally:
        if not stopped:
            server.stop(grace=None)


def test_success_says_what_happened(server):
    holder = locked_session(server)
    try:
        device, _, _ = stubs(holder.channel)
        reply = device.Activate(control_pb2.ActivateRequest(), timeout=10)
        assert reply.ret_val.ret_msg == "drives on"
        reply = device.GetMaxAccelerations(settings_pb2.GetMaxAccelerationsRequest(), timeout=5)
        assert reply.ret_val.ret_msg and reply.units.linear and len(reply.max_joint_accels) == 6
        assert list(reply.max_joint_accels) == pytest.approx(server.device.arm.max_acceleration)
        assert reply.max_world_linear_accel == pytest.approx(
            server.device.arm.max_linear_acceleration)
    finally:
        holder.close()


def test_every_setter_says_what_it_set_in_the_clients_units(server):
    holder = locked_session(server)
    try:
        device, io, _ = stubs(holder.channel)
        said = [device.SetSpeed(settings_pb2.SetSpeedRequest(
                    speed=40, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED), timeout=5),
                device.SetSpeed(settings_pb2.SetSpeedRequest(
                    speed=0.2, attribute=types_pb2.SPEED_TYPE_LINEAR_SPEED), timeout=5),
                device.SetUnits(settings_pb2.SetUnitsRequest(
                    linear_units=types_pb2.LINEAR_UNIT_MILLIMETERS,
                    angular_units=types_pb2.ANGULAR_UNIT_DEGREES), timeout=5),
                device.SetAcceleration(settings_pb2.SetAccelerationRequest(
                    accel=90, attribute=types_pb2.ACCEL_TYPE_ANGULAR_ACCEL), timeout=5),
                device.SetAcceleration(settings_pb2.SetAccelerationRequest(
                    accel=50, attribute=types_pb2.ACCEL_TYPE_PERCENT_ACCEL), timeout=5),
                device.SetToolOffset(settings_pb2.SetToolOffsetRequest(
                    offset=types_pb2.Pose(z=100)), timeout=5),
                device.SetWorldCartesianFrame(settings_pb2.SetWorldCartesianFrameRequest(
                    frame=types_pb2.Pose(x=-250.5, yaw=90)), timeout=5),
                io.SetDigitalIO(digital_io_service_pb2.SetDigitalIORequest(
                    type="output", unit_id=2, bits_on=0x5, bits_off=0x2), timeout=5)]
    finally:
        holder.close()
    assert [reply.ret_val.ret_msg for reply in said] == [
        "speed 40 %", "linear speed 0.2 m/s", "units millimeters and degrees",
        "angular acceleration 90 deg/s^2", "acceleration 50 %",
        "tool offset x 0, y 0, z 100 mm; roll 0, pitch 0, yaw 0 deg",
        "world frame x -250.5, y 0, z 0 mm; roll 0, pitch 0, yaw 90 deg",
        "output unit 2: bits 0x5 on, 0x2 off"]


def test_an_unexpected_failure_is_internal_with_error_info_never_unknown(server):
    def broken():
        raise RuntimeError("a bug")   # the status a bug in a handler must produce

    server.device.motion_control_state = broken
    with grpc.insecure_channel(server.target) as channel:
        device, _, _ = stubs(channel)
        with pytest.raises(grpc.RpcError) as failed:
            device.GetMotionControlState(settings_pb2.GetMotionControlStateRequest(), timeout=5)
    assert failed.value.code() is grpc.StatusCode.INTERNAL
    assert error_info(failed.value).reason == "INTERNAL"
    assert "RuntimeError: a bug" in failed.value.details()
