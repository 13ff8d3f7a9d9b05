"""Issue 16: TLS, role tokens, the audit log, rate limits and the refusal to listen on the
network unprotected. Real servers (lock-step clock) on free loopback ports, real TLS."""
from __future__ import annotations

import asyncio
import json
import subprocess
import sys
import time
from types import SimpleNamespace

import grpc
import numpy as np
import pytest
from grpc_health.v1 import health_pb2, health_pb2_grpc

from landscape.cell.certs import make_certificates
from landscape.cell.tokens import make_tokens
from landscape.client import (AsyncSession, ClientTLS, Session, open_aio_channel, open_channel,
                              read_token)
from landscape.server.api import services
from landscape.server.app import StartupError
from landscape.server.security.auth import Role, required_role
from landscape.server.config import SecurityConfig
from landscape.server.api.stream_caps import Cap
from landscape.server.device.states import State
from landscape.server.security.tls import exposure_problem
from landscape.v1 import (control_pb2, device_service_pb2_grpc, motion_pb2, state_service_pb2,
                          state_service_pb2_grpc, types_pb2)

from support import bus_history, error_info, start_server, wait_until

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
GOAL = [0.3, -0.2, 1.8, 0.1, 1.2, -0.4]
ROLES = ("viewer", "operator", "admin")


@pytest.fixture(scope="module")
def keys(tmp_path_factory):
    """A development CA with server and client certificates, a stranger CA with its own
    client, and one token per role."""
    folder = tmp_path_factory.mktemp("keys")
    certs = make_certificates(folder / "certs", clients=["client"])
    stranger = make_certificates(folder / "stranger", clients=["intruder"])
    files = make_tokens(folder / "tokens")
    return SimpleNamespace(certs=certs, stranger=stranger, folder=folder / "tokens",
                           token={role: read_token(files[role]) for role in ROLES})


def _security(keys, tmp_path, **overrides) -> SecurityConfig:
    settings = dict(tls_cert=str(keys.certs.server_cert), tls_key=str(keys.certs.server_key),
                    tokens=str(keys.folder), audit_log=str(tmp_path / "audit.log"))
    return SecurityConfig(**{**settings, **overrides})


@pytest.fixture
def secured(keys, tmp_path):
    server = start_server(security=_security(keys, tmp_path))
    yield server
    server.stop(grace=None)


def _tls(keys) -> ClientTLS:
    return ClientTLS(ca=str(keys.certs.ca))


def _device(channel):
    return device_service_pb2_grpc.DeviceServiceStub(channel)


def _refusal(call) -> grpc.RpcError:
    with pytest.raises(grpc.RpcError) as refused:
        call()
    return refused.value


def _move(channel, lease: str):
    return _device(channel).MoveAbsolute(
        motion_pb2.MoveAbsoluteRequest(point_name="p1", frame=JOINT, values=GOAL),
        metadata=[("landscape-lease", lease)], timeout=10)



def test_without_a_token_or_as_a_viewer_a_move_is_refused_and_nothing_moves(secured, keys):
    with open_channel(secured.target, _tls(keys), keys.token["operator"]) as channel, \
            Session(channel, "operator") as operator:
        lease = operator.lock()
        _device(operator.channel).Activate(control_pb2.ActivateRequest(), timeout=10)
        before = secured.device.feedback().position.copy()

        # Even with the holder's lease in hand: no token, or a viewer's, is not enough.
        with open_channel(secured.target, _tls(keys)) as anonymous:
            refused = _refusal(lambda: _move(anonymous, lease))
        assert refused.code() is grpc.StatusCode.UNAUTHENTICATED
        assert error_info(refused).reason == "UNAUTHENTICATED"
        with open_channel(secured.target, _tls(keys), keys.token["viewer"]) as viewer:
            refused = _refusal(lambda: _move(viewer, lease))
        assert refused.code() is grpc.StatusCode.PERMISSION_DENIED
        info = error_info(refused)
        assert (info.reason, info.metadata["role"], info.metadata["needs"]) == (
            "ROLE_TOO_LOW", "viewer", "operator")
        time.sleep(0.3)    # the lock-step clock runs many cycles meanwhile
        assert secured.device.state is State.RESTING
        assert np.max(np.abs(secured.device.feedback().position - before)) < 1e-6  # servo hold
        assert not [e for e in bus_history(secured) if e.event_id.startswith("command_")]

        # The operator's token, over TLS: the same move runs.
        reply = _move(channel, lease)
        assert reply.ret_val.ret_code == types_pb2.RETURN_CODE_CMD_STARTED_OK
        wait_until(lambda: np.max(np.abs(secured.device.feedback().position - GOAL)) < 1e-3
                   and secured.device.state is State.RESTING, timeout=60)


def test_a_viewer_reads_and_watches_but_opens_no_session(secured, keys):
    with open_channel(secured.target, _tls(keys), keys.token["viewer"]) as channel:
        state = _device(channel).GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=10)
        assert state.state == types_pb2.DEVICE_STATE_UNLOCKED
        stream = state_service_pb2_grpc.StateServiceStub(channel).StreamState(
            state_service_pb2.StreamStateRequest(rate_hz=50), timeout=10)
        assert next(stream).WhichOneof("message") == "started"
        assert len(next(stream).sample.joint_positions) == 6
        stream.cancel()
        with pytest.raises(grpc.RpcError) as refused:
            Session(channel, "viewer").open()
        assert refused.value.code() is grpc.StatusCode.PERMISSION_DENIED


def test_anyone_watching_may_press_the_estop_an_operator_releases_it(secured, keys):
    """The e-stop is every role's to press (anyone watching may stop the cell), an operator's
    to release; the door, the rest of the panel and Reset stay an admin's."""
    def panel(channel, action):
        return _device(channel).OperatePanel(control_pb2.OperatePanelRequest(action=action),
                                             timeout=10)

    with open_channel(secured.target, _tls(keys), keys.token["viewer"]) as viewer, \
            open_channel(secured.target, _tls(keys), keys.token["operator"]) as operator, \
            open_channel(secured.target, _tls(keys), keys.token["admin"]) as admin:
        refused = _refusal(lambda: panel(operator, control_pb2.PANEL_ACTION_OPEN_DOOR))
        assert error_info(refused).reason == "ROLE_TOO_LOW"
        assert secured.device.state is State.UNLOCKED
        assert panel(viewer, control_pb2.PANEL_ACTION_PRESS_ESTOP).estop_pressed
        wait_until(lambda: secured.device.state is State.ERROR)
        refused = _refusal(lambda: panel(viewer, control_pb2.PANEL_ACTION_RELEASE_ESTOP))
        info = error_info(refused)
        assert (info.reason, info.metadata["role"], info.metadata["needs"]) == (
            "ROLE_TOO_LOW", "viewer", "operator")
        assert secured.device.status().estop
        assert not panel(operator, control_pb2.PANEL_ACTION_RELEASE_ESTOP).estop_pressed
        refused = _refusal(lambda: _device(operator).Reset(control_pb2.ResetRequest(), timeout=10))
        assert error_info(refused).reason == "ROLE_TOO_LOW"
        assert secured.device.state is State.ERROR
        _device(admin).Reset(control_pb2.ResetRequest(), timeout=60)
        wait_until(lambda: secured.device.state is State.UNLOCKED, timeout=30)
        assert panel(admin, control_pb2.PANEL_ACTION_OPEN_DOOR).door_open


def test_health_needs_no_token(secured, keys):
    with open_channel(secured.target, _tls(keys)) as channel:
        reply = health_pb2_grpc.HealthStub(channel).Check(health_pb2.HealthCheckRequest(),
                                                          timeout=10)
    assert reply.status == health_pb2.HealthCheckResponse.SERVING


@pytest.mark.parametrize("how", ["a stranger CA", "plaintext"])
def test_a_client_that_does_not_trust_the_ca_cannot_connect(secured, keys, how):
    tls = ClientTLS(ca=str(keys.stranger.ca)) if how == "a stranger CA" else None
    with open_channel(secured.target, tls, keys.token["admin"]) as channel:
        refused = _refusal(lambda: _device(channel).GetDeviceState(
            control_pb2.GetDeviceStateRequest(), timeout=5))
    assert refused.code() is grpc.StatusCode.UNAVAILABLE


def test_mutual_tls_wants_a_client_certificate_from_the_cell_ca(keys, tmp_path):
    server = start_server(security=_security(keys, tmp_path, mtls=True,
                                             tls_ca=str(keys.certs.ca)))
    try:
        ours = keys.certs.clients["client"]
        theirs = keys.stranger.clients["intruder"]
        for cert_key, works in ((None, False), (theirs, False), (ours, True)):
            cert, key = (str(cert_key[0]), str(cert_key[1])) if cert_key else (None, None)
            tls = ClientTLS(str(keys.certs.ca), cert, key)
            with open_channel(server.target, tls, keys.token["viewer"]) as channel:
                call = lambda: _device(channel).GetDeviceState(  # noqa: E731
                    control_pb2.GetDeviceStateRequest(), timeout=5)
                if works:
                    assert call().state == types_pb2.DEVICE_STATE_UNLOCKED
                else:
                    assert _refusal(call).code() is grpc.StatusCode.UNAVAILABLE
    finally:
        server.stop(grace=None)


def test_tokens_work_on_plaintext_loopback_for_sync_and_asyncio_clients(keys, tmp_path):
    server = start_server(security=SecurityConfig(tokens=str(keys.folder)))
    try:
        with open_channel(server.target, token=keys.token["operator"]) as channel, \
                Session(channel, "sync") as session:
            session.lock()
            _device(session.channel).Release(control_pb2.ReleaseRequest(), timeout=10)

        async def asyncio_client():
            async with open_aio_channel(server.target, token=keys.token["operator"]) as channel:
                async with AsyncSession(channel, "aio") as session:
                    await session.lock()
                    await _device(channel).Release(control_pb2.ReleaseRequest(),
                                                   metadata=session.metadata(), timeout=10)
            async with open_aio_channel(server.target) as channel:
                with pytest.raises(grpc.aio.AioRpcError) as refused:
                    await AsyncSession(channel, "anonymous").open()
                return refused.value.code()
        assert asyncio.run(asyncio_client()) is grpc.StatusCode.UNAUTHENTICATED
    finally:
        server.stop(grace=None)


def test_listening_off_loopback_without_tls_and_tokens_refuses_to_start(tmp_path, keys):
    done = subprocess.run([sys.executable, "-m", "landscape.server", "--address", "0.0.0.0",
                           "--port", "0", "--clock", "lockstep", "--paths", str(tmp_path / "p"),
                           "--audit-log", ""], capture_output=True, text=True, timeout=60)
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert "refusing to listen on 0.0.0.0 without TLS" in lines[0] and "--insecure" in lines[0]
    tls_only = SecurityConfig(tls_cert=str(keys.certs.server_cert),
                              tls_key=str(keys.certs.server_key))
    with pytest.raises(StartupError, match=r"without tokens \(--tokens\)"):
        start_server(address="0.0.0.0", security=tls_only)
    assert exposure_problem("192.168.1.20", SecurityConfig(insecure=True)) is None
    assert exposure_problem("::1", SecurityConfig()) is None
    assert exposure_problem("localhost", SecurityConfig()) is None


def test_unusable_token_files_and_certificates_stop_the_start_naming_the_file(tmp_path, keys):
    folder = tmp_path / "tokens"
    folder.mkdir()
    (folder / "operator.tokens").write_text("# ours\nshort alice\n")
    with pytest.raises(StartupError, match=r"operator\.tokens:2: a token is at least 16"):
        start_server(security=SecurityConfig(tokens=str(folder)))
    with pytest.raises(StartupError, match="none of viewer.tokens"):
        start_server(security=SecurityConfig(tokens=str(tmp_path)))
    with pytest.raises(StartupError, match=r"TLS: cannot read the TLS certificate .*nowhere"):
        start_server(security=SecurityConfig(tls_cert=str(tmp_path / "nowhere.pem"),
                                             tls_key=str(keys.certs.server_key)))


def test_the_audit_log_names_every_mutating_call_refused_ones_included(keys, tmp_path):
    server = start_server(security=_security(keys, tmp_path))
    made = []    # (rpc, who, result) of every call that needs more than a viewer

    def call(who, rpc, result, invoke):
        try:
            invoke()
            got = "OK"
        except grpc.RpcError as error:
            got = error.code().name
        assert got == result, (rpc, who, got)
        made.append((rpc, who, result))

    try:
        tls = _tls(keys)
        with open_channel(server.target, tls) as anonymous, \
                open_channel(server.target, tls, keys.token["viewer"]) as viewer, \
                open_channel(server.target, tls, keys.token["operator"]) as channel:
            lock = control_pb2.LockRequest(session_id="s", session_secret="x" * 16)
            call("anonymous", "DeviceService/Lock", "UNAUTHENTICATED",
                 lambda: _device(anonymous).Lock(lock, timeout=10))
            _device(viewer).GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=10)
            session = Session(channel, "operator").open()
            call("operator", "DeviceService/Lock", "OK", session.lock)
            operator = _device(session.channel)
            call("operator", "DeviceService/Activate", "OK",
                 lambda: operator.Activate(control_pb2.ActivateRequest(), timeout=10))
            call("viewer", "DeviceService/MoveAbsolute", "PERMISSION_DENIED",
                 lambda: _move(viewer, session.lease))
            call("operator", "DeviceService/MoveArc", "INVALID_ARGUMENT",
                 lambda: operator.MoveArc(motion_pb2.MoveArcRequest(), timeout=10))
            call("operator", "DeviceService/OperatePanel", "PERMISSION_DENIED",
                 lambda: operator.OperatePanel(control_pb2.OperatePanelRequest(
                     action=control_pb2.PANEL_ACTION_OPEN_DOOR), timeout=10))
            call("operator", "DeviceService/MoveAbsolute", "OK",
                 lambda: _move(channel, session.lease))
            wait_until(lambda: server.device.state is State.RESTING, timeout=60)
            call("operator", "DeviceService/Deactivate", "OK",
                 lambda: operator.Deactivate(control_pb2.DeactivateRequest(), timeout=10))
            call("operator", "DeviceService/Release", "OK",
                 lambda: operator.Release(control_pb2.ReleaseRequest(), timeout=10))
            session.close()
            wait_until(lambda: not server.device.sessions.get(session.session_id))
    finally:
        server.stop(grace=None)      # the audit log is written out
    records = [json.loads(line) for line in (tmp_path / "audit.log").read_text().splitlines()]
    for record in records:
        print(record)
    logged = [(r["rpc"], r["who"], r["result"].split(":")[0]) for r in records
              if r["rpc"] != "SessionService/Connect" and r["result"] != "ADMITTED"]
    assert logged == made
    # What changes something was written before it ran; what makes the arm safe, and what
    # was refused before it could run, only when it ended.
    admitted = [r["rpc"].split("/")[1] for r in records if r["result"] == "ADMITTED"]
    assert admitted == ["Lock", "Activate", "MoveArc", "MoveAbsolute"], admitted
    sessions = [r["result"].split(":")[0] for r in records if r["rpc"] == "SessionService/Connect"]
    assert sessions == ["OPEN", "CANCELLED"]
    assert all(r["time"].endswith("Z") and r["peer"].startswith("ipv4:127.0.0.1:")
               for r in records)
    assert "x" * 16 not in (tmp_path / "audit.log").read_text()     # secrets are blanked
    assert not any(r["rpc"].endswith("GetDeviceState") for r in records)


def test_the_audit_log_rotates_by_size(keys, tmp_path):
    server = start_server(security=SecurityConfig(audit_log=str(tmp_path / "audit.log"),
                                                  audit_max_bytes=2000, audit_backups=2))
    try:
        with grpc.insecure_channel(server.target) as channel:
            for _ in range(30):
                _refusal(lambda: _device(channel).Activate(control_pb2.ActivateRequest(),
                                                           timeout=10))
    finally:
        server.stop(grace=None)
    names = sorted(p.name for p in tmp_path.glob("audit.log*"))
    assert names == ["audit.log", "audit.log.1", "audit.log.2"]
    assert all(p.stat().st_size <= 2000 for p in tmp_path.glob("audit.log*"))


def test_a_client_beyond_its_rate_is_refused_but_its_stops_get_through(tmp_path):
    """A client is its address: a fresh connection from it draws on the same bucket."""
    server = start_server(security=SecurityConfig(rate_limit=2.0, rate_burst=5))
    own = [("grpc.use_local_subchannel_pool", 1)]   # a connection of its own
    try:
        with grpc.insecure_channel(server.target) as channel, \
                grpc.insecure_channel(server.target, options=own) as fresh:
            grpc.channel_ready_future(fresh).result(timeout=10)   # connected before the burst
            device = _device(channel)
            for _ in range(5):
                device.GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=10)
            refused = _refusal(lambda: _device(fresh).GetDeviceState(
                control_pb2.GetDeviceStateRequest(), timeout=10))
            assert refused.code() is grpc.StatusCode.RESOURCE_EXHAUSTED
            assert error_info(refused).reason == "RATE_LIMITED"
            # A stop is never limited: the state table answers it (nothing moves here).
            stop = _refusal(lambda: device.StopMotion(motion_pb2.StopMotionRequest(),
                                                       timeout=10))
            assert error_info(stop).reason in ("WRONG_STATE", "NOT_LOCK_HOLDER")
    finally:
        server.stop(grace=None)


def test_streams_are_capped_per_identity_across_connections(keys, tmp_path):
    caps = {"watch": Cap(per_client=2, total=100), "session": Cap(per_client=2, total=100)}
    server = start_server(stream_caps=caps, security=SecurityConfig(tokens=str(keys.folder)))
    channels, streams = [], []
    try:
        def watch(token):
            channel = open_channel(server.target, token=token)
            channels.append(channel)
            stream = state_service_pb2_grpc.StateServiceStub(channel).StreamState(
                state_service_pb2.StreamStateRequest(rate_hz=10), timeout=30)
            streams.append(stream)
            return next(stream)

        watch(keys.token["viewer"])
        watch(keys.token["viewer"])
        refused = _refusal(lambda: watch(keys.token["viewer"]))
        assert refused.code() is grpc.StatusCode.RESOURCE_EXHAUSTED
        assert watch(keys.token["admin"]).WhichOneof("message") == "started"   # another one
    finally:
        for stream in streams:
            stream.cancel()
        for channel in channels:
            channel.close()
        server.stop(grace=None)


def test_every_rpc_of_the_contract_needs_a_role_and_health_none():
    roles = {method.name: required_role(f"/{spec.full_name}/{method.name}")
             for spec in services.ALL for method in spec.descriptor.methods}
    assert {name for name, role in roles.items() if role is Role.ADMIN} == {"OperatePanel",
                                                                            "Reset", "ReadAuditLog"}
    assert roles["MoveAbsolute"] is roles["Lock"] is roles["Connect"] is Role.OPERATOR
    assert roles["GetRobotPosition"] is roles["StreamState"] is roles["Subscribe"] is Role.VIEWER
    assert roles["ListPaths"] is roles["GetPath"] is roles["SolvePose"] is Role.VIEWER
    assert roles["AcknowledgeAlarm"] is Role.OPERATOR
    assert Role.PUBLIC not in roles.values()
    assert required_role("/grpc.health.v1.Health/Check") is Role.PUBLIC
    assert required_role("/landscape.v1.DeviceService/NotThere") is Role.ADMIN
