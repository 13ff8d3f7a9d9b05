"""Acknowledging alarms on the device (EventService.AcknowledgeAlarm): one AlarmAcknowledged
event each, seen by every subscriber and named by who acknowledged; once only; recorded in the
audit; an operator's. Real servers on the lock-step clock, on loopback."""
from __future__ import annotations

import json
import queue
import threading

import grpc
import pytest

from landscape.client import open_channel
from landscape.server.config import SecurityConfig
from landscape.server.events import alarms
from landscape.v1 import control_pb2, event_service_pb2 as pb

from support import bus_history, error_info, start_server, stubs

PRESS = control_pb2.OperatePanelRequest(action=control_pb2.PANEL_ACTION_PRESS_ESTOP)
FRONT_END = (("landscape-client", "supervisor"), ("landscape-on-behalf-of", "alice"))


class Watcher:
    """A subscriber of its own channel, from the first event."""

    def __init__(self, channel):
        self.stream = stubs(channel)[2].Subscribe(pb.SubscribeRequest(after_sequence=0))
        self.events: queue.Queue = queue.Queue()
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self):
        try:
            for reply in self.stream:
                self.events.put(reply.event)
        except grpc.RpcError:
            pass

    def next_of(self, kind: str, timeout: float = 10.0):
        while True:
            event = self.events.get(timeout=timeout)
            if event.WhichOneof("detail") == kind:
                return event


def estop_alarm(server, channel) -> int:
    """Press the e-stop; the sequence of its alarm."""
    stubs(channel)[0].OperatePanel(PRESS, timeout=10)
    return next(e.sequence for e in bus_history(server)
                if e.event_id == "alarm" and e.detail.code == alarms.ESTOP)


def acknowledge(channel, sequence, metadata=FRONT_END):
    return stubs(channel)[2].AcknowledgeAlarm(pb.AcknowledgeAlarmRequest(sequence=sequence),
                                              metadata=metadata, timeout=10)


def refusal(call) -> grpc.RpcError:
    with pytest.raises(grpc.RpcError) as refused:
        call()
    return refused.value


@pytest.fixture
def server():
    running = start_server()
    yield running
    running.stop(grace=None)


def test_every_subscriber_sees_who_acknowledged_an_alarm_and_only_once(server):
    channels = [grpc.insecure_channel(server.target) for _ in range(3)]
    watchers = [Watcher(channel) for channel in channels[:2]]
    alarm = estop_alarm(server, channels[2])

    reply = acknowledge(channels[2], alarm)
    assert reply.newly and reply.acknowledgement.alarm_sequence == alarm
    by = reply.acknowledgement.by
    assert by.startswith("ipv4:127.0.0.1:")          # tokens off: the peer
    assert (reply.acknowledgement.client, reply.acknowledgement.on_behalf_of) == (
        "supervisor", "alice")
    for watcher in watchers:
        event = watcher.next_of("alarm_acknowledged")
        assert event.sequence == reply.event_sequence and event.event_id == "alarm_acknowledged"
        assert event.alarm_acknowledged == reply.acknowledgement
        assert list(event.data) == [str(alarm), by, "supervisor", "alice"]

    again = acknowledge(channels[0], alarm, metadata=(("landscape-on-behalf-of", "bob"),))
    assert not again.newly
    assert (again.event_sequence, again.acknowledgement) == (reply.event_sequence,
                                                             reply.acknowledgement)
    assert "already" in again.ret_val.ret_msg
    made = [e for e in bus_history(server) if e.event_id == "alarm_acknowledged"]
    assert [e.sequence for e in made] == [reply.event_sequence]
    # A subscriber that comes later replays the alarm and its acknowledgement.
    late = Watcher(channels[1])
    assert late.next_of("alarm").sequence == alarm
    assert late.next_of("alarm_acknowledged").alarm_acknowledged.alarm_sequence == alarm
    for channel in channels:
        channel.close()


def test_what_is_not_a_kept_alarm_is_refused_and_changes_nothing(server):
    channel = grpc.insecure_channel(server.target)
    alarm = estop_alarm(server, channel)
    not_an_alarm = next(e.sequence for e in bus_history(server) if e.event_id != "alarm")
    before = server.bus.last_sequence
    for sequence, said in ((not_an_alarm, "not an alarm"), (before + 5, "not yet published"),
                           (0, "no longer kept")):
        error = refusal(lambda: acknowledge(channel, sequence))
        assert error.code() is grpc.StatusCode.INVALID_ARGUMENT, error.details()
        assert error_info(error).reason == "NOT_FOUND" and said in error.details()
    assert server.bus.last_sequence == before
    assert acknowledge(channel, alarm).newly
    channel.close()


def test_an_operator_acknowledges_by_name_in_the_audit_and_a_viewer_may_not(keys, tmp_path):
    log = tmp_path / "audit.log"
    server = start_server(security=SecurityConfig(tokens=str(keys.tokens), audit_log=str(log)))
    try:
        admin = open_channel(server.target, token=keys.token("admin"))
        alarm = estop_alarm(server, admin)
        viewer = open_channel(server.target, token=keys.token("viewer"))
        error = refusal(lambda: acknowledge(viewer, alarm))
        assert error.code() is grpc.StatusCode.PERMISSION_DENIED
        assert error_info(error).reason == "ROLE_TOO_LOW"
        operator = open_channel(server.target, token=keys.token("operator"))
        reply = acknowledge(operator, alarm)           # no session, no lock: none needed
        assert reply.newly and reply.acknowledgement.by == "operator"
        assert reply.acknowledgement.on_behalf_of == "alice"
    finally:
        server.stop(grace=None)
    records = [json.loads(line) for line in log.read_text().splitlines()]
    acks = [r for r in records if r["rpc"] == "EventService/AcknowledgeAlarm"]
    assert [(r["who"], r["role"], r["via"], r["for"], r["result"]) for r in acks] == [
        ("viewer", "viewer", "supervisor", "alice", acks[0]["result"]),
        ("operator", "operator", "supervisor", "alice", "ADMITTED"),
        ("operator", "operator", "supervisor", "alice", "OK")]
    assert acks[0]["result"].startswith("PERMISSION_DENIED")
    assert f"sequence: {alarm}" in acks[1]["request"]
