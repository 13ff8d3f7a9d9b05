"""A device's events, read once for a whole program: one EventService.Subscribe kept open, and
the commands it started followed by their command ids.

The subscription starts live (replaying the device's history costs about 0.7 ms per kept
event; `replay` asks for it, for a program that shows the history) and is `ready` once the
device has registered it (it sends the call's headers then), so
a command started after `ready()` cannot have events the feed misses. When the stream breaks it
is opened again after the last event seen, so nothing is missed across the gap; a device that
restarted (it no longer has that event: OUT_OF_RANGE) is followed live again, its command ids
starting afresh (with `replay`, from its first kept event). Every event also goes to the
`listeners` (a supervisor shows them), and each time the stream is registered or fails the
`status_listeners` hear (code, details): (OK, "") once registered.

A started command's end is waited for here (`wait`, `follow`), raced against the end of the
session that started it: a command the device aborted because that session was lost raises
the session's SessionEnded (the device's reason), never a bare CommandAborted.
"""
from __future__ import annotations

import asyncio
import contextlib
import logging
from typing import AsyncIterator

import grpc

from landscape.client.errors import CommandTimeout, ServerUnavailable, SessionEnded
from landscape.client.feed import Feed
from landscape.client.tracking import ALARM_GRACE, CommandLog
from landscape.v1 import event_service_pb2 as pb
from landscape.v1 import event_service_pb2_grpc

log = logging.getLogger(__name__)

RETRY_FIRST, RETRY_MAX = 0.25, 2.0   # s between attempts to reopen the stream, growing
SETTLE_GRACE = 2.0    # s for a command's final event once its session ended (the device ends it)
LOSS_GRACE = 5.0      # s for a session's end after the device said its lock holder is gone


class EventFeed(Feed[pb.Event]):
    def __init__(self, channel: grpc.aio.Channel, metadata=(), replay: bool = False):
        super().__init__("landscape-events")
        self._stub = event_service_pb2_grpc.EventServiceStub(channel)
        self._metadata = tuple(metadata)
        self._replay = replay
        self.log = CommandLog()
        self.failure = ""                    # why the stream is down, while it is
        self._live = asyncio.Event()
        self._changed = asyncio.Condition()

    async def ready(self, timeout: float) -> None:
        """Until the device has registered the subscription; ServerUnavailable if it does not
        within `timeout` s (the device is unreachable)."""
        try:
            async with asyncio.timeout(timeout):
                await self._live.wait()
        except TimeoutError:
            raise ServerUnavailable(f"the device's event stream is not open: "
                                    f"{self.failure or 'no answer'}",
                                    grpc.StatusCode.UNAVAILABLE) from None

    def wake(self) -> None:
        """Waiters look again (a session ended)."""
        asyncio.ensure_future(self._notify())

    # ---- the stream ------------------------------------------------------------------------

    async def _run(self) -> None:
        pause = RETRY_FIRST
        first: int | None = 0 if self._replay else None   # where a stream with no past starts
        after = first                                     # then after the last event seen
        while True:
            try:
                await self._stream(after)
            except grpc.aio.AioRpcError as error:
                if error.code() is grpc.StatusCode.OUT_OF_RANGE:
                    log.info("events: %s; following the device afresh", error.details())
                    self.log = CommandLog()  # a restarted device: its ids start again
                    after, pause = first, 0.0
                    continue
                if not self.failure:
                    log.warning("event stream: %s: %s", error.code().name, error.details())
                self.failure = f"{error.code().name}: {error.details()}"
                self._tell(error.code(), error.details())
            finally:
                self._live.clear()
            after = self.log.last_sequence or first
            await asyncio.sleep(pause)
            pause = min(max(2 * pause, RETRY_FIRST), RETRY_MAX)

    async def _stream(self, after: int | None) -> None:
        call = self._stub.Subscribe(pb.SubscribeRequest(after_sequence=after),
                                    metadata=self._metadata)
        try:
            await call.initial_metadata()    # sent once the device has subscribed us
            self._live.set()
            self.failure = ""
            self._tell(grpc.StatusCode.OK, "")
            async for reply in call:
                self.log.record(reply.event)
                self._hand_on(reply.event)
                await self._notify()
        finally:
            call.cancel()

    async def _notify(self) -> None:
        async with self._changed:
            self._changed.notify_all()

    # ---- following a command ---------------------------------------------------------------

    def events(self, command_id: str) -> list[pb.Event]:
        return self.log.events(command_id)

    async def wait(self, command_id: str, timeout: float | None, session=None) -> pb.Event:
        """The command's done event; CommandFailed / CommandAborted for its other ends,
        SessionEnded if `session` (its lock holder) was lost, CommandTimeout after `timeout` s
        (None: no limit)."""
        try:
            async with asyncio.timeout(timeout):
                await self._until(lambda: self.log.final(command_id) is not None
                                  or _ended(session), command_id)
        except TimeoutError:
            raise CommandTimeout(f"{command_id} did not end in time (it may still run)") from None
        if self.log.final(command_id) is None:      # its session ended first: so does it
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(SETTLE_GRACE):
                    await self._until(lambda: self.log.final(command_id) is not None, command_id)
        final = self.log.final(command_id)
        if final is not None and final.command.phase == pb.CommandEvent.Phase.PHASE_DONE:
            return final
        lost = await self._lost(command_id, session)
        if lost is not None:
            raise lost
        if final is None:
            raise SessionEnded(f"{session.end_details}, before {command_id} ended",
                               session.end_status)
        with contextlib.suppress(TimeoutError):   # a failure's alarm follows its event
            async with asyncio.timeout(ALARM_GRACE):
                await self._until(lambda: not self.log.needs_alarm(command_id), command_id)
        return self.log.outcome(command_id)

    async def follow(self, command_id: str, timeout: float | None,
                     session=None) -> AsyncIterator[pb.Event]:
        """Each of the command's events as it comes, ending with the done event (raises as
        `wait`)."""
        loop = asyncio.get_running_loop()
        deadline = None if timeout is None else loop.time() + timeout
        seen = 0
        while self.log.final(command_id) is None or seen < len(self.log.events(command_id)):
            try:
                async with asyncio.timeout_at(deadline):
                    await self._until(lambda: len(self.log.events(command_id)) > seen
                                      or _ended(session), command_id)
            except TimeoutError:
                raise CommandTimeout(f"{command_id} did not end in time") from None
            fresh = self.log.events(command_id)[seen:]
            seen += len(fresh)
            for event in fresh:
                yield event
            if not fresh:            # its session ended: wait says how it all ended
                break
        await self.wait(command_id, None if deadline is None else max(0.0, deadline - loop.time()),
                        session)

    async def _lost(self, command_id: str, session) -> SessionEnded | None:
        """Why the command's session was lost, if it was: the device ended the session, or
        said the lock holder was gone while the command ran (then the session's own end,
        which carries the device's reason, is on its way)."""
        if session is None:
            return None
        if session.lost is not None:
            return session.lost
        alarm = self.log.lock_lost_while_running(command_id)
        if alarm is None:
            return None
        return await session.loss(LOSS_GRACE) or SessionEnded(alarm.message, held_lock=True)

    async def _until(self, predicate, command_id: str) -> None:
        async with self._changed:
            while not predicate():
                self.log.check_not_lost(command_id)
                await self._changed.wait()


def _ended(session) -> bool:
    return session is not None and session.ended.is_set()
