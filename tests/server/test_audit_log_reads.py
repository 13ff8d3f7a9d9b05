"""The audit log read back (AuditService.ReadAuditLog): the rotated files and the newest, oldest
first, in whole lines, filtered by time; an administrator's only, and itself audited. Real
servers on the lock-step clock, on loopback."""
from __future__ import annotations

import json

import grpc
import pytest
from google.protobuf import timestamp_pb2

from landscape.client import Session, open_channel
from landscape.server.config import SecurityConfig
from landscape.v1 import audit_service_pb2 as pb, audit_service_pb2_grpc, settings_pb2, types_pb2

from support import error_info, start_server, stubs, wait_until


def read(channel, **fields) -> list[pb.ReadAuditLogResponse]:
    stub = audit_service_pb2_grpc.AuditServiceStub(channel)
    return list(stub.ReadAuditLog(pb.ReadAuditLogRequest(**fields), timeout=30))


def lines(chunks) -> list[dict]:
    for chunk in chunks:
        assert chunk.records.endswith(b"\n")      # whole lines only
    return [json.loads(line) for chunk in chunks for line in chunk.records.splitlines()]


@pytest.fixture
def audited(keys, tmp_path):
    """A server with tokens and a small audit log (rotated every few records), after an
    operator's session set the speed ten times."""
    log = tmp_path / "audit.log"
    server = start_server(security=SecurityConfig(tokens=str(keys.tokens), audit_log=str(log),
                                                  audit_max_bytes=2000, audit_backups=3))
    with Session(open_channel(server.target, token=keys.token("operator")), "op") as session:
        session.lock()
        for speed in range(10, 30):
            stubs(session.channel)[0].SetSpeed(settings_pb2.SetSpeedRequest(
                speed=speed, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED), timeout=10)
    yield server, log
    server.stop(grace=None)


def test_an_admin_reads_every_file_oldest_first_with_this_call_in_it(audited, keys):
    server, log = audited
    admin = open_channel(server.target, token=keys.token("admin"))
    chunks = read(admin)
    # Rotated three times at least, so every file kept is there, the oldest first. (This
    # call's own record may rotate them once more before they are opened: compared with what
    # they hold, not with a listing taken before.)
    names = list(dict.fromkeys(c.file for c in chunks))
    assert names == ["audit.log.3", "audit.log.2", "audit.log.1", "audit.log"]
    records = lines(chunks)
    speeds = [float(r["request"].split()[1]) for r in records
              if r["rpc"].endswith("SetSpeed") and r["result"] == "OK"]
    assert speeds and speeds == list(range(int(speeds[0]), 30))     # in order, none missing
    mine = records[-1]
    assert (mine["rpc"], mine["who"], mine["role"], mine["result"]) == (
        "AuditService/ReadAuditLog", "admin", "admin", "OPEN")
    # Once over, the call's result is written too.
    wait_until(lambda: any(json.loads(line)["rpc"] == "AuditService/ReadAuditLog"
                           and json.loads(line)["result"] == "OK"
                           for line in log.read_text().splitlines()))


def test_since_and_until_keep_the_records_of_that_time(audited, keys):
    server, log = audited
    admin = open_channel(server.target, token=keys.token("admin"))
    every = lines(read(admin))
    times = sorted({r["time"] for r in every})
    since, until = times[2], times[-3]
    stamps = {}
    for key, text in (("since", since), ("until", until)):
        stamps[key] = timestamp_pb2.Timestamp()
        stamps[key].FromJsonString(text)
    kept = lines(read(admin, **stamps))
    assert kept and all(since <= r["time"] < until for r in kept)
    assert len(kept) == sum(1 for r in every if since <= r["time"] < until)


def test_only_an_admin_may_read_it(audited, keys):
    server, _ = audited
    for role in ("viewer", "operator"):
        with pytest.raises(grpc.RpcError) as refused:
            read(open_channel(server.target, token=keys.token(role)))
        assert refused.value.code() is grpc.StatusCode.PERMISSION_DENIED
        assert error_info(refused.value).reason == "ROLE_TOO_LOW"


def test_a_server_without_an_audit_log_says_so():
    server = start_server()
    try:
        with pytest.raises(grpc.RpcError) as refused:
            read(grpc.insecure_channel(server.target))
    finally:
        server.stop(grace=None)
    assert refused.value.code() is grpc.StatusCode.FAILED_PRECONDITION
    assert error_info(refused.value).reason == "NOT_OFFERED"
    assert "--audit-log" in refused.value.details()
