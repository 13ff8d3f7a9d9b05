"""Following started commands on the event stream: what each command id has done so far.

A non-blocking command (moves, paths) answers CMD_STARTED_OK with a command id; its started,
tag-reached, paused, resumed and final (done / failed / aborted) events follow on
EventService.Subscribe, and a failure also raises an alarm naming the id. `CommandLog` keeps
that per command id; the sync and asyncio clients feed it from one subscription each, opened
before their first command so no event of theirs can be missed.

The subscription is live (a replay of the device's history costs about 0.7 ms per kept event:
7 s for 10,000), opened before the client locks. Once it has delivered any event it is
registered, and sees every later one; the client's lock and activation publish events, so by
its first command it has. Only if none came does the client replay the history to be sure.
"""
from __future__ import annotations

from collections import OrderedDict

from landscape.client.errors import CommandAborted, CommandFailed, EventsMissed
from landscape.v1 import event_service_pb2 as pb

Phase = pb.CommandEvent.Phase
FINAL_PHASES = frozenset({Phase.PHASE_DONE, Phase.PHASE_FAILED, Phase.PHASE_ABORTED})

# After a failed event, how long the log waits for the alarm that explains it, in seconds.
ALARM_GRACE = 1.0


class CommandLog:
    """Events and alarms per command id, for the newest `keep` commands. Not thread-safe:
    the clients guard it with their own lock or run it on one event loop."""

    def __init__(self, keep: int = 1024):
        self._keep = keep
        self._events: OrderedDict[str, list[pb.Event]] = OrderedDict()
        self._alarms: dict[str, pb.Alarm] = {}
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
