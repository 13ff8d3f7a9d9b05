"""A started command, for the blocking client: the asyncio core's AsyncCommand, waited for on
the Robot's loop thread.

    move = robot.move_absolute([0.5, 0, 1.57, 0, 1.57, 0], Frame.JOINT)
    done = move.wait(timeout=30)          # the done event, or CommandFailed with the alarm
    for event in path.follow(timeout=60): # each started / tag-reached / ... event as it comes
        ...
"""
from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator

from landscape.client.aio import AsyncCommand
from landscape.client.loop_thread import LoopThread
from landscape.v1 import event_service_pb2, types_pb2


@dataclass
class Command:
    """A started non-blocking command: its id (named by its events) and the reply's RetVal."""
    _command: AsyncCommand = field(repr=False)
    _thread: LoopThread = field(repr=False)

    @property
    def command_id(self) -> str:
        return self._command.command_id

    @property
    def command(self) -> str:
        return self._command.command

    @property
    def ret_val(self) -> types_pb2.RetVal:
        return self._command.ret_val

    def wait(self, timeout: float | None = 60.0) -> event_service_pb2.Event:
        """Its done event; raises CommandFailed (with the alarm) / CommandAborted when it ends
        otherwise, SessionEnded if its session was lost, CommandTimeout after `timeout` s."""
        return self._thread.run(self._command.wait(timeout))

    def follow(self, timeout: float | None = 60.0) -> Iterator[event_service_pb2.Event]:
        """Each of its events as it comes, ending with the done event (raises as `wait`)."""
        return self._thread.iterate(self._command.follow(timeout))

    @property
    def events(self) -> list[event_service_pb2.Event]:
        """Its events so far."""
        return self._command.events
