"""The audit log (issue 25.5): it fails closed (a call that would move the arm or change a
setting is refused while its record cannot be written; a stop never is), each record names the
person and the front end, refused authentication is rate limited and summarised; rate limits
belong to the identity (issue 31.3). Real servers (lock-step clock) on loopback; the full disk
is a small tmpfs the test mounts (conftest.small_disk)."""
from __future__ import annotations

import json
import subprocess
import sys
import time

import grpc
import numpy as np
import pytest

from landscape.client import Session, open_channel
from landscape.server.events import alarms
from landscape.server.config import SecurityConfig
from landscape.server.device.states import State
from landscape.v1 import control_pb2, motion_pb2, settings_pb2, types_pb2

from support import bus_history, error_info, start_server, stubs

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
GOAL = [0.3, -0.2, 1.8, 0.1, 1.2, -0.4]
SPEED = settings_pb2.SetSpeedRequest(speed=37, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED)


class Headers(grpc.UnaryUnaryClientInterceptor, grpc.UnaryStreamClientInterceptor,
              grpc.StreamUnaryClientInterceptor, grpc.StreamStreamClientInterceptor):
    """The identity headers (identity.md) on every call of a channel, as a front end sends
    them."""

    def __init__(self, client: str, on_behalf_of: str | None = None):
        self.pairs = [("landscape-client", client)]
        if on_behalf_of is not None:
            self.pairs.append(("landscape-on-behalf-of", on_behalf_of))

    def _with(self, details):
        return details._replace(metadata=[*(details.metadata or ()), *self.pairs])

    def intercept_unary_unary(self, continuation, details, request):
        return continuation(self._with(details), request)

    def intercept_unary_stream(self, continuation, details, request):
        return continuation(self._with(details), request)

    def intercept_stream_unary(self, continuation, details, requests):
        return continuation(self._with(details), requests)

    def intercept_stream_stream(self, continuation, details, requests):
        return continuation(self._with(details), requests)


def _refusal(call) -> grpc.RpcError:
    with pytest.raises(grpc.RpcError) as refused:
        call()
    return refused.value


def _records(path) -> list[dict]:
    """Every record of an audit log; each line must be one whole JSON object."""
    return [json.loads(line) for line in path.read_text().splitlines()]


def _audit_alarms(server) -> list:
    return [e.detail for e in bus_history(server)
            if e.event_id == "alarm" and e.detail.code == alarms.AUDIT]


def test_a_full_audit_disk_refuses_what_would_move_but_never_a_stop(small_disk):
    log = small_disk.path / "audit.log"
    server = start_server(security=SecurityConfig(audit_log=str(log)))
    try:
        channel = grpc.insecure_channel(server.target)
        session = Session(channel, "operator").open()
        session.lock()
        device = stubs(session.channel)[0]
        device.Activate(control_pb2.ActivateRequest(), timeout=10)
        before = server.device.feedback().position.copy()
        small_disk.fill()
        # The file's last page may still take a few records: call until one is refused.
        refused = None
        for _ in range(200):
            try:
                device.SetSpeed(SPEED, timeout=10)
            except grpc.RpcError as error:
                refused = error
                break
        assert refused is not None, "200 settings changed with the audit's disk full"
        assert refused.code() is grpc.StatusCode.UNAVAILABLE, refused
        assert error_info(refused).reason == "AUDIT_UNAVAILABLE"
        assert "audit" in refused.details(), refused.details()
        move = _refusal(lambda: device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            frame=JOINT, values=GOAL), timeout=10))
        assert move.code() is grpc.StatusCode.UNAVAILABLE
        time.sleep(0.3)
        assert server.device.state is State.RESTING
        assert np.max(np.abs(server.device.feedback().position - before)) < 1e-6
        (alarm,) = _audit_alarms(server)              # once, not per refused call
        print(alarm.message)
        # Safety first: a stop, an abort and powering down are never refused for the audit.
        stop = _refusal(lambda: device.StopMotion(motion_pb2.StopMotionRequest(), timeout=10))
        assert error_info(stop).reason == "WRONG_STATE"    # nothing moves: the state says so
        device.AbortMotion(motion_pb2.AbortMotionRequest(), timeout=10)
        device.Deactivate(control_pb2.DeactivateRequest(), timeout=10)
        assert server.device.state is State.INACTIVE
        small_disk.free()                                   # the disk frees up: it recovers
        device.SetSpeed(SPEED, timeout=10)
        assert len(_audit_alarms(server)) == 2
        session.close()
    finally:
        server.stop(grace=None)
    records = _records(log)
    calls = [(r["rpc"].split("/")[1], r["result"].split(":")[0]) for r in records]
    # The stops were written once the disk had room again, and the refusals too.
    for call in (("StopMotion", "FAILED_PRECONDITION"), ("AbortMotion", "OK"),
                 ("Deactivate", "OK"), ("MoveAbsolute", "UNAVAILABLE")):
        assert call in calls, (call, calls)
    # Nothing ran unrecorded: every SetSpeed that ran was written before it ran.
    admitted = [r for r in records if r["rpc"].endswith("SetSpeed") and r["result"] == "ADMITTED"]
    done = [r for r in records if r["rpc"].endswith("SetSpeed") and r["result"] == "OK"]
    assert len(admitted) == len(done) >= 1


def test_sigterm_with_the_audit_disk_full_exits_cleanly(small_disk, tmp_path):
    log = small_disk.path / "audit.log"
    proc = subprocess.Popen([sys.executable, "-m", "landscape.server", "--port", "0",
                             "--clock", "lockstep", "--paths", str(tmp_path / "p.sqlite3"),
                             "--audit-log", str(log)],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        for line in proc.stdout:
            if "listening on" in line:
                break
        with grpc.insecure_channel(line.split()[-1]) as channel, \
                Session(channel, "operator") as session:
            session.lock()
            small_disk.fill()
            device = stubs(session.channel)[0]
            for _ in range(200):
                try:
                    device.SetSpeed(SPEED, timeout=10)
                except grpc.RpcError:
                    break
        proc.terminate()
        err = proc.communicate(timeout=60)[1]
    finally:
        proc.kill()
    assert proc.returncode == 0, err[-3000:]
    assert "Traceback" not in err and "Logging error" not in err, err[-3000:]
    assert "audit" in err, err[-3000:]          # it said what it could not write
    _records(log)                               # no record cut in half


def test_each_record_names_the_person_and_the_front_end_escaped(keys, tmp_path):
    log = tmp_path / "audit.log"
    server = start_server(security=SecurityConfig(tokens=str(keys.tokens), audit_log=str(log)))
    try:
        gateway = grpc.intercept_channel(open_channel(server.target, token=keys.token("operator")),
                                         Headers("crcl-gateway", "crcl 10.0.0.7:5555"))
        with Session(gateway, "gateway") as session:
            session.lock()
            stubs(session.channel)[0].SetSpeed(SPEED, timeout=10)
        # gRPC carries printable ASCII in a header: anything else comes percent-encoded.
        forged = "M%C3%BCller%0A{\"who\": \"admin\"}%1B[2K" + "x" * 300
        viewer = grpc.intercept_channel(open_channel(server.target, token=keys.token("viewer")),
                                        Headers("supervisor", forged))
        _refusal(lambda: stubs(viewer)[0].Release(control_pb2.ReleaseRequest(), timeout=10))
    finally:
        server.stop(grace=None)
    text = log.read_text()
    records = _records(log)
    for record in records:
        print(record)
    speed = next(r for r in records if r["rpc"].endswith("SetSpeed") and r["result"] == "OK")
    assert (speed["who"], speed["role"], speed["via"], speed["for"]) == (
        "operator", "operator", "crcl-gateway", "crcl 10.0.0.7:5555")
    release = next(r for r in records if r["rpc"].endswith("Release"))
    assert (release["who"], release["role"], release["via"]) == ("viewer", "viewer", "supervisor")
    assert release["for"].startswith("Müller\\n{") and len(release["for"]) == 128
    assert "\n" not in release["for"] and "\x1b" not in release["for"]
    assert len(text.splitlines()) == len(records)


def test_without_tokens_who_is_the_peer(tmp_path):
    log = tmp_path / "audit.log"
    server = start_server(security=SecurityConfig(audit_log=str(log)))
    try:
        channel = grpc.intercept_channel(grpc.insecure_channel(server.target),
                                         Headers("landscape-cli", "alice@cell1"))
        with Session(channel, "cli") as session:
            session.lock()
    finally:
        server.stop(grace=None)
    lock = next(r for r in _records(log) if r["rpc"].endswith("Lock") and r["result"] == "OK")
    assert lock["who"].startswith("ipv4:127.0.0.1:")
    assert (lock["via"], lock["for"]) == ("landscape-cli", "alice@cell1")


def test_refused_tokens_are_rate_limited_per_address_and_summarised(keys, tmp_path):
    log = tmp_path / "audit.log"
    server = start_server(security=SecurityConfig(tokens=str(keys.tokens), audit_log=str(log),
                                                  rate_limit=5.0, rate_burst=10))
    codes = []
    try:
        with open_channel(server.target, token="not-a-token-of-this-cell-0123456789") as bad, \
                open_channel(server.target, token=keys.token("viewer")) as good:
            for _ in range(60):
                codes.append(_refusal(lambda: stubs(bad)[0].Release(
                    control_pb2.ReleaseRequest(), timeout=10)).code().name)
            # The same address with a token of the cell is not held back by the refusals.
            stubs(good)[0].GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=10)
    finally:
        server.stop(grace=None)
    print(codes)
    assert codes[0] == "UNAUTHENTICATED" and codes[-1] == "RESOURCE_EXHAUSTED"
    assert codes.count("UNAUTHENTICATED") <= 15
    refused = [r for r in _records(log) if r["who"] == "anonymous"]
    for record in refused:
        print(record)
    assert 1 <= len(refused) <= 3, "one line at the first refusal, then a summary"
    assert "60" in refused[-1]["result"] or "59" in refused[-1]["result"], refused[-1]


def test_front_ends_on_one_address_are_not_throttled_by_each_other(tmp_path):
    """Without tokens a client is its address and its name: a CLI that floods the device runs
    out of its own budget, not the gateway's; a front end's budget is sized by name."""
    server = start_server(security=SecurityConfig(rate_limit=2.0, rate_burst=5,
                                                  rate_limits={"crcl-gateway": 100.0}))
    state = control_pb2.GetDeviceStateRequest()
    try:
        raw = grpc.insecure_channel(server.target)
        cli = stubs(grpc.intercept_channel(raw, Headers("landscape-cli")))[0]
        gateway = stubs(grpc.intercept_channel(raw, Headers("crcl-gateway")))[0]
        supervisor = stubs(grpc.intercept_channel(raw, Headers("supervisor")))[0]
        for _ in range(5):
            cli.GetDeviceState(state, timeout=10)
        assert error_info(_refusal(lambda: cli.GetDeviceState(state, timeout=10))).reason \
            == "RATE_LIMITED"
        supervisor.GetDeviceState(state, timeout=10)          # a budget of its own
        for _ in range(50):                                   # and the gateway a bigger one
            gateway.GetDeviceState(state, timeout=10)
    finally:
        server.stop(grace=None)


def test_the_command_line_sizes_named_clients():
    # In a child: importing the server's main module blocks the stop signals of its process.
    parse = ("from landscape.server.__main__ import parse_args; import sys; "
             "print(parse_args(sys.argv[1:])[0].security.rate_limits)")
    done = subprocess.run([sys.executable, "-c", parse, "--rate-limit-for", "crcl-gateway=5000",
                           "--rate-limit-for", "supervisor=2500.5"],
                          capture_output=True, text=True, timeout=60)
    assert done.stdout.strip() == "{'crcl-gateway': 5000.0, 'supervisor': 2500.5}", done.stderr
    for bad in ("crcl-gateway", "=5", "cli=0", "cli=fast"):
        done = subprocess.run([sys.executable, "-c", parse, "--rate-limit-for", bad],
                              capture_output=True, text=True, timeout=60)
        assert done.returncode == 2 and "NAME=CALLS_PER_SECOND" in done.stderr, done.stderr
