"""Following started commands on the event stream: what each command id has done so far.

A non-blocking command (moves, paths) answers CMD_STARTED_OK with a command id; its started,
tag-reached, paused, resumed and final (done / failed / aborted) events follow on
EventService.Subscribe, and a failure also raises an alarm naming the id. `CommandLog` keeps
that per command id; the client core feeds it from one subscription per device (event_feed.py).

It also keeps the device's lock-holder-lost alarms: the device publishes one as the lock
holder's session ends, before it stops the arm, so a command aborted after such an alarm was
aborted because its session (the lock holder's, as it ran) was lost.
"""
from __future__ import annotations

from collections import OrderedDict

from landscape.client.errors import CommandAborted, CommandFailed, EventsMissed
from landscape.v1 import event_service_pb2 as pb

Phase = pb.CommandEvent.Phase
FINAL_PHASES = frozenset({Phase.PHASE_DONE, Phase.PHASE_FAILED, Phase.PHASE_ABORTED})

# After a failed event, how long the log waits for the alarm that explains it, in seconds.
ALARM_GRACE = 1.0
LOCK_HOLDER_LOST = 101      # the device's alarm code (server/alarms.py): the holder's session ended


class CommandLog:
    """Events and alarms per command id, for the newest `keep` commands. Not thread-safe:
    the clients guard it with their own lock or run it on one event loop."""

    def __init__(self, keep: int = 1024):
        self._keep = keep
        self._events: OrderedDict[str, list[pb.Event]] = OrderedDict()
        self._alarms: dict[str, pb.Alarm] = {}
        self._lock_lost: list[tuple[int, pb.Alarm]] = []   # (sequence, alarm), the newest few
        self.lost = 0               # events the subscription lost (it fell behind)
        self.last_sequence = 0
        self.received = 0           # events delivered: one proves the subscription is live

    def record(self, event: pb.Event) -> None:
        self.received += 1
        self.last_sequence = max(self.last_sequence, event.sequence)
        kind = event.WhichOneof("detail")
        if kind == "command":
            self._bucket(event.command.command_id).append(event)
        elif kind == "alarm" and event.alarm.command_id:
            self._alarms[event.alarm.command_id] = event.alarm
            self._bucket(event.alarm.command_id)
        elif kind == "alarm" and event.alarm.code == LOCK_HOLDER_LOST:
            self._lock_lost = [*self._lock_lost[-7:], (event.sequence, event.alarm)]
        elif kind == "events_lost":
            lost = event.events_lost
            self.lost += lost.last_sequence - lost.first_sequence + 1

    def events(self, command_id: str) -> list[pb.Event]:
        return list(self._events.get(command_id, ()))

    def final(self, command_id: str) -> pb.Event | None:
        for event in reversed(self._events.get(command_id, ())):
            if event.command.phase in FINAL_PHASES:
                return event
        return None

    def alarm(self, command_id: str) -> pb.Alarm | None:
        return self._alarms.get(command_id)

    def lock_lost_while_running(self, command_id: str) -> pb.Alarm | None:
        """The lock-holder-lost alarm published after the command began and before its end:
        it held the lock then, so the lock lost was its own."""
        events = self._events.get(command_id)
        if not events:
            return None
        end = self.final(command_id)
        last = end.sequence if end is not None else self.last_sequence
        return next((alarm for sequence, alarm in self._lock_lost
                     if events[0].sequence < sequence < last), None)

    def needs_alarm(self, command_id: str) -> bool:
        """A failure is final, but its alarm (published right after) has not come yet."""
        final = self.final(command_id)
        return (final is not None and final.command.phase == Phase.PHASE_FAILED
                and command_id not in self._alarms)

    def outcome(self, command_id: str) -> pb.Event:
        """The done event; raises CommandFailed / CommandAborted for the other endings.
        Call once `final(command_id)` is set."""
        event = self.final(command_id)
        phase = event.command.phase
        if phase == Phase.PHASE_DONE:
            return event
        alarm = self.alarm(command_id)
        what = f"{event.command.command} {event.command.point_name}".strip()
        if phase == Phase.PHASE_ABORTED:
            raise CommandAborted(f"{what} ({command_id}) was aborted", event, alarm)
        detail = (alarm.message if alarm else "") or event.command.message or "failed"
        raise CommandFailed(f"{what} ({command_id}) failed: {detail}", event, alarm)

    def check_not_lost(self, command_id: str) -> None:
        if self.lost and self.final(command_id) is None:
            raise EventsMissed(f"the event stream lost {self.lost} events while waiting for "
                               f"{command_id}; ask GetDeviceState whether it still runs")

    def _bucket(self, command_id: str) -> list[pb.Event]:
        bucket = self._events.get(command_id)
        if bucket is None:
            bucket = self._events[command_id] = []
            while len(self._events) > self._keep:
                old, _ = self._events.popitem(last=False)
                self._alarms.pop(old, None)
        return bucket
