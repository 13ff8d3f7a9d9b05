"""Started commands for the blocking client: a handle per command and the thread that feeds them.

    move = robot.move_absolute([0.5, 0, 1.57, 0, 1.57, 0], Frame.JOINT)
    done = move.wait(timeout=30)          # the done event, or CommandFailed with the alarm
    for event in path.follow(timeout=60): # each started / tag-reached / ... event as it comes
        ...
"""
from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Iterator

from landscape.client.errors import CommandTimeout, LandscapeError, SessionEnded
from landscape.client.streams import EventStream
from landscape.client.tracking import ALARM_GRACE, CommandLog
from landscape.v1 import event_service_pb2, types_pb2


class CommandTracker:
    """Reads one event subscription on a thread into a CommandLog, and wakes waiters."""

    def __init__(self, stream: EventStream):
        self._stream = stream
        self._log = CommandLog()
        self._changed = threading.Condition()
        self._ended: LandscapeError | None = None
        self._thread = threading.Thread(target=self._run, daemon=True, name="landscape-events")
        self._thread.start()

    def close(self) -> None:
        self._stream.close()

    def _run(self) -> None:
        error: LandscapeError = SessionEnded("the event stream ended")
        try:
            for event in self._stream:
                with self._changed:
                    self._log.record(event)
                    self._changed.notify_all()
        except LandscapeError as failure:
            error = failure
        with self._changed:
            self._ended = error
            self._changed.notify_all()

    def wait(self, command_id: str, timeout: float) -> event_service_pb2.Event:
        deadline = time.monotonic() + timeout
        with self._changed:
            self._wait_for(lambda: self._log.final(command_id) is not None, command_id, deadline)
            # A failure's alarm follows its failed event: give it a moment to arrive.
            self._changed.wait_for(lambda: not self._log.needs_alarm(command_id) or self._ended,
                                   ALARM_GRACE)
            return self._log.outcome(command_id)

    def follow(self, command_id: str, timeout: float) -> Iterator[event_service_pb2.Event]:
        deadline = time.monotonic() + timeout
        seen = 0
        while True:
            with self._changed:
                self._wait_for(lambda: len(self._log.events(command_id)) > seen, command_id,
                               deadline)
                fresh = self._log.events(command_id)[seen:]
                seen += len(fresh)
                final = self._log.final(command_id) is not None
            yield from fresh
            if final:
                self.wait(command_id, max(0.0, deadline - time.monotonic()))  # raises on failure
                return

    def wait_live(self, timeout: float) -> bool:
        """Whether the subscription delivered an event within `timeout` s (see tracking.py)."""
        with self._changed:
            self._changed.wait_for(lambda: self._log.received or self._ended, timeout)
            return self._log.received > 0

    def events(self, command_id: str) -> list[event_service_pb2.Event]:
        with self._changed:
            return self._log.events(command_id)

    def _wait_for(self, predicate, command_id: str, deadline: float) -> None:
        """With the lock held: until predicate(); raises if the stream ends or time is up."""
        while not predicate():
            self._log.check_not_lost(command_id)
            if self._ended is not None:
                raise self._ended
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise CommandTimeout(f"{command_id} did not end in time (it may still run)")
            self._changed.wait(remaining)


@dataclass
class Command:
    """A started non-blocking command: its id (named by its events) and the reply's RetVal."""
    command_id: str
    command: str
    ret_val: types_pb2.RetVal
    _tracker: CommandTracker = field(repr=False)

    def wait(self, timeout: float = 60.0) -> event_service_pb2.Event:
        """Its done event; raises CommandFailed (with the alarm) / CommandAborted when it ends
        otherwise, CommandTimeout after `timeout` seconds."""
        return self._tracker.wait(self.command_id, timeout)

    def follow(self, timeout: float = 60.0) -> Iterator[event_service_pb2.Event]:
        """Each of its events as it comes, ending with the done event (raises as `wait`)."""
        return self._tracker.follow(self.command_id, timeout)

    @property
    def events(self) -> list[event_service_pb2.Event]:
        """Its events so far."""
        return self._tracker.events(self.command_id)
