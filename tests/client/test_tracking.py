"""CommandLog: what the event stream says about each command, and how a command ends."""
from __future__ import annotations

import pytest

from landscape.client.errors import CommandAborted, CommandFailed, EventsMissed
from landscape.client.tracking import CommandLog
from landscape.v1 import event_service_pb2 as pb

Phase = pb.CommandEvent.Phase


def command(seq: int, cid: str, phase, message: str = "") -> pb.Event:
    return pb.Event(sequence=seq, event_id="x", command=pb.CommandEvent(
        command_id=cid, command="MoveAbsolute", phase=phase, point_name="p", message=message))


def test_done_is_the_outcome_and_other_commands_do_not_mix_in():
    log = CommandLog()
    log.record(command(1, "a", Phase.PHASE_STARTED))
    log.record(command(2, "b", Phase.PHASE_STARTED))
    assert log.final("a") is None
    log.record(command(3, "a", Phase.PHASE_DONE))
    assert log.outcome("a").sequence == 3
    assert [e.sequence for e in log.events("a")] == [1, 3]


def test_a_failure_waits_for_its_alarm_and_raises_with_it():
    log = CommandLog()
    log.record(command(1, "a", Phase.PHASE_FAILED, "collision"))
    assert log.needs_alarm("a")
    log.record(pb.Event(sequence=2, alarm=pb.Alarm(code=-1, message="a: collision with table",
                                                   command_id="a")))
    assert not log.needs_alarm("a")
    with pytest.raises(CommandFailed, match="collision with table") as failed:
        log.outcome("a")
    assert failed.value.alarm.code == -1


def test_aborted_and_lost_events():
    log = CommandLog(keep=2)
    log.record(command(1, "a", Phase.PHASE_ABORTED))
    with pytest.raises(CommandAborted):
        log.outcome("a")
    log.record(pb.Event(sequence=9, events_lost=pb.EventsLost(first_sequence=2, last_sequence=8)))
    with pytest.raises(EventsMissed):
        log.check_not_lost("b")
    log.record(command(10, "c", Phase.PHASE_STARTED))
    log.record(command(11, "d", Phase.PHASE_STARTED))
    assert log.events("a") == []   # only the newest `keep` commands are kept



def test_any_delivered_event_proves_the_subscription_live():
    log = CommandLog()
    assert log.received == 0
    log.record(pb.Event(sequence=7, state_change=pb.StateChange(to_state="inactive")))
    assert log.received == 1 and log.last_sequence == 7


def test_a_lock_holder_lost_while_a_command_ran_explains_its_abort():
    log = CommandLog()
    log.record(pb.Event(sequence=1, alarm=pb.Alarm(code=101, message="before: not this one")))
    log.record(command(2, "a", Phase.PHASE_STARTED))
    assert log.lock_lost_while_running("a") is None
    log.record(pb.Event(sequence=3, alarm=pb.Alarm(
        code=101, message="lock holder x disconnected (no keep-alive for 2 s)")))
    log.record(command(4, "a", Phase.PHASE_ABORTED))
    assert "no keep-alive" in log.lock_lost_while_running("a").message
    log.record(command(5, "b", Phase.PHASE_STARTED))
    log.record(command(6, "b", Phase.PHASE_ABORTED))
    assert log.lock_lost_while_running("b") is None   # an abort of its own
