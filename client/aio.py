"""`AsyncRobot`: the asyncio twin of `Robot`, on a grpc.aio channel.

    async with AsyncRobot("127.0.0.1:50051", "my-program") as robot:   # or tls=, token=
        async with robot.control():
            move = await robot.move_absolute([0.5, 0, 1.57, 0, 1.57, 0], Frame.JOINT)
            await move.wait(timeout=30)
        async for event in robot.events():
            ...

The command methods are Robot's (commands.py); here each returns an awaitable. Must be used
from one event loop.
"""
from __future__ import annotations

import asyncio
import contextlib
import logging
from dataclasses import dataclass, field
from typing import AsyncIterator, Sequence

import grpc

from landscape.client.aio_session import AsyncRsvpHandler, AsyncSession
from landscape.client.commands import (DEVICE, EVENTS, IO, RELINQUISH_MAX_STEPS,
                                       RELINQUISH_STEP, DeviceCommands, jog_request)
from landscape.client.credentials import ClientTLS, open_aio_channel
from landscape.client.errors import (CommandRefused, CommandTimeout, LandscapeError,
                                     NotAllowed, NotLockHolder, ServerUnavailable, SessionEnded,
                                     from_rpc_error)
from landscape.client.streams import state_request, subscribe_request
from landscape.client.tracking import ALARM_GRACE, CommandLog
from landscape.client.values import DeviceState, Frame
from landscape.v1 import (device_service_pb2_grpc, digital_io_service_pb2_grpc, event_service_pb2,
                          event_service_pb2_grpc, sensing_pb2, state_service_pb2,
                          state_service_pb2_grpc, types_pb2)

log = logging.getLogger(__name__)

DEFAULT_TIMEOUT = 30.0   # seconds, for a blocking call that names none
FENCE_TIMEOUT = 2.0      # seconds for the command subscription to prove live (tracking.py)


class _AsyncTracker:
    """Reads one event subscription in a task into a CommandLog and wakes waiters."""

    def __init__(self, call):
        self._call = call
        self._log = CommandLog()
        self._changed = asyncio.Condition()
        self._ended: LandscapeError | None = None
        self._task = asyncio.create_task(self._run())

    async def close(self) -> None:
        self._call.cancel()
        self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._task

    async def _run(self) -> None:
        error: LandscapeError = SessionEnded("the event stream ended")
        try:
            async for reply in self._call:
                async with self._changed:
                    self._log.record(reply.event)
                    self._changed.notify_all()
        except grpc.aio.AioRpcError as failure:
            error = from_rpc_error(failure)
        finally:
            self._ended = error
            async with self._changed:
                self._changed.notify_all()

    async def wait(self, command_id: str, timeout: float) -> event_service_pb2.Event:
        try:
            async with asyncio.timeout(timeout):
                await self._until(lambda: self._log.final(command_id) is not None, command_id)
        except TimeoutError:
            raise CommandTimeout(f"{command_id} did not end in time (it may still run)") from None
        with contextlib.suppress(TimeoutError):   # a failure's alarm follows its event
            async with asyncio.timeout(ALARM_GRACE):
                await self._until(lambda: not self._log.needs_alarm(command_id), command_id)
        return self._log.outcome(command_id)

    async def follow(self, command_id: str, timeout: float):
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        seen = 0
        while self._log.final(command_id) is None or seen < len(self._log.events(command_id)):
            try:
                async with asyncio.timeout_at(deadline):
                    await self._until(lambda: len(self._log.events(command_id)) > seen,
                                      command_id)
            except TimeoutError:
                raise CommandTimeout(f"{command_id} did not end in time") from None
            fresh = self._log.events(command_id)[seen:]
            seen += len(fresh)
            for event in fresh:
                yield event
        await self.wait(command_id, max(0.0, deadline - loop.time()))   # raises on failure

    async def wait_live(self, timeout: float) -> bool:
        """Whether the subscription delivered an event within `timeout` s (see tracking.py)."""
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout), self._changed:
                await self._changed.wait_for(lambda: self._log.received or self._ended)
        return self._log.received > 0

    def events(self, command_id: str) -> list[event_service_pb2.Event]:
        return self._log.events(command_id)

    async def _until(self, predicate, command_id: str) -> None:
        async with self._changed:
            while not predicate():
                self._log.check_not_lost(command_id)
                if self._ended is not None:
                    raise self._ended
                await self._changed.wait()


@dataclass
class AsyncCommand:
    """A started non-blocking command (see command.Command), awaited on the event loop."""
    command_id: str
    command: str
    ret_val: types_pb2.RetVal
    _tracker: _AsyncTracker = field(repr=False)

    async def wait(self, timeout: float = 60.0) -> event_service_pb2.Event:
        """Its done event; raises CommandFailed / CommandAborted / CommandTimeout."""
        return await self._tracker.wait(self.command_id, timeout)

    def follow(self, timeout: float = 60.0) -> AsyncIterator[event_service_pb2.Event]:
        """`async for` each of its events, ending with the done event (raises as `wait`)."""
        return self._tracker.follow(self.command_id, timeout)

    @property
    def events(self) -> list[event_service_pb2.Event]:
        return self._tracker.events(self.command_id)


class AsyncRobot(DeviceCommands):
    """Robot for asyncio programs. target: "host:port" (with `tls` and `token` as Robot's), or
    an open grpc.aio.Channel (then the caller closes it). on_rsvp may be a plain or an async
    function."""

    def __init__(self, target: str | grpc.aio.Channel, client_name: str = "landscape-client", *,
                 on_rsvp: AsyncRsvpHandler | None = None, tls: ClientTLS | None = None,
                 token: str | None = None):
        self._own_channel = isinstance(target, str)
        if not self._own_channel and (tls is not None or token):
            raise ValueError("TLS and the token belong to the channel: give them to "
                             "open_aio_channel, or give AsyncRobot a \"host:port\"")
        self.target = target if self._own_channel else "the channel given"
        self._credentials = (tls, token)
        self._given = None if self._own_channel else target
        self.client_name = client_name
        self._on_rsvp = on_rsvp
        self._channel: grpc.aio.Channel | None = None
        self._session: AsyncSession | None = None
        self._no_session: NotAllowed | None = None   # why there is no session, if refused
        self._tracker: _AsyncTracker | None = None

    async def open(self, timeout: float = 10.0) -> "AsyncRobot":
        self._channel = (open_aio_channel(self.target, *self._credentials) if self._own_channel
                         else self._given)
        try:
            await asyncio.wait_for(self._channel.channel_ready(), timeout)
        except asyncio.TimeoutError:
            if self._own_channel:
                await self._channel.close()
            raise ServerUnavailable(f"no device server at {self.target} answered within "
                                    f"{timeout} s", grpc.StatusCode.UNAVAILABLE) from None
        self._events = event_service_pb2_grpc.EventServiceStub(self._channel)
        session = AsyncSession(self._channel, self.client_name, self._on_rsvp)
        try:
            self._session = await session.open(timeout)
        except grpc.aio.AioRpcError as error:
            refused = from_rpc_error(error)
            if not isinstance(refused, NotAllowed):
                await self.close()
                raise refused from None
            self._no_session = refused   # a viewer's token: reads and streams only
        self._stubs = {DEVICE: device_service_pb2_grpc.DeviceServiceStub(self._channel),
                       IO: digital_io_service_pb2_grpc.DigitalIOServiceStub(self._channel),
                       EVENTS: self._events}
        self._state = state_service_pb2_grpc.StateServiceStub(self._channel)
        return self

    async def close(self) -> None:
        if self._tracker is not None:
            await self._tracker.close()
        if self._session is not None:
            await self._session.close()
        if self._channel is not None and self._own_channel:
            await self._channel.close()

    async def __aenter__(self) -> "AsyncRobot":
        return await self.open()

    async def __aexit__(self, *exc) -> None:
        await self.close()

    @property
    def session(self) -> AsyncSession | None:
        """None when the role token may not open a session (see Robot.session)."""
        return self._session

    def _lease(self) -> tuple[tuple[str, str], ...]:
        return self._session.metadata() if self._session else ()

    def _track_commands(self, after_sequence: int | None = None) -> _AsyncTracker:
        """As Robot._track_commands: opened before the first lock or command."""
        if self._tracker is None:
            self._tracker = _AsyncTracker(self._events.Subscribe(
                subscribe_request(after_sequence)))
        return self._tracker

    async def _live_tracker(self) -> _AsyncTracker:
        """As Robot._live_tracker."""
        tracker = self._track_commands()
        if not await tracker.wait_live(FENCE_TIMEOUT):
            log.warning("no event arrived on the command subscription; replaying the device's")
            await tracker.close()
            self._tracker = None
            tracker = self._track_commands(after_sequence=0)
        return tracker

    async def lock(self, timeout: float = 10.0) -> str:
        if self._session is None:
            raise self._no_session
        self._track_commands()   # before the lock, whose event then proves it live
        try:
            return await self._session.lock(timeout)
        except grpc.aio.AioRpcError as error:
            raise from_rpc_error(error) from None

    @contextlib.asynccontextmanager
    async def control(self, activate: bool = True):
        """Lock (and activate) for the body; afterwards stop, deactivate and release."""
        await self.lock()
        try:
            if activate:
                await self.activate()
            yield self
        finally:
            await self.relinquish()

    async def relinquish(self) -> DeviceState:
        state = DeviceState.UNLOCKED
        for _ in range(RELINQUISH_MAX_STEPS):
            state = DeviceState((await self.get_device_state()).state)
            step = RELINQUISH_STEP.get(state)
            if step is None:
                return state
            try:
                await getattr(self, step)()
            except (NotLockHolder, NotAllowed):   # not (or no longer) ours to hand back
                return state
            except CommandRefused as refused:
                log.debug("relinquish: %s refused: %s", step, refused)
        return state

    async def events(self, after_sequence: int | None = None, timeout: float | None = None
                     ) -> AsyncIterator[event_service_pb2.Event]:
        """`async for` events and alarms, live or from after `after_sequence` (timeout: the
        stream raises RpcTimeout after that many seconds)."""
        call = self._events.Subscribe(subscribe_request(after_sequence), timeout=timeout)
        try:
            async for reply in call:
                yield reply.event
        except grpc.aio.AioRpcError as error:
            raise from_rpc_error(error) from None
        finally:
            call.cancel()

    async def live_state(self, rate_hz: float = 10.0, frame: Frame | None = None,
                         units: types_pb2.Units | None = None, sensors: Sequence[str] = (),
                         timeout: float | None = None
                         ) -> AsyncIterator[state_service_pb2.StateSample]:
        """`async for` state samples (the StreamStarted terms are skipped)."""
        call = self._state.StreamState(state_request(rate_hz, frame, units, sensors),
                                       timeout=timeout)
        try:
            async for message in call:
                if message.WhichOneof("message") == "sample":
                    yield message.sample
        except grpc.aio.AioRpcError as error:
            raise from_rpc_error(error) from None
        finally:
            call.cancel()

    async def jog(self, velocities, frame: Frame) -> AsyncIterator[sensing_pb2.JogResponse]:
        """`async for` a JogResponse (joints, pose) per message, the deadman held while
        `velocities` (percent of each axis maximum; an async iterable paces the stream, as the
        deadman wants a message every few cycles; a plain one is sent as fast as it goes)
        lasts, then released. Needs manual_control(TEACHPENDANT)."""
        async def requests():
            if hasattr(velocities, "__aiter__"):
                async for velocity in velocities:
                    yield jog_request(velocity, frame)
            else:
                for velocity in velocities:
                    yield jog_request(velocity, frame)
            yield jog_request(None, frame)

        call = self._stubs[DEVICE].Jog(requests(), metadata=self._lease())
        try:
            async for reply in call:
                yield reply
        except grpc.aio.AioRpcError as error:
            raise from_rpc_error(error) from None
        finally:
            call.cancel()

    async def _invoke(self, service, rpc, request, started, timeout):
        tracker = await self._live_tracker() if started else None
        try:
            reply = await getattr(self._stubs[service], rpc)(
                request, metadata=self._lease(), timeout=timeout or DEFAULT_TIMEOUT)
        except grpc.aio.AioRpcError as error:
            raise from_rpc_error(error) from None
        if started:
            return AsyncCommand(reply.ret_val.command_id, rpc, reply.ret_val, tracker)
        return reply

    def _call(self, service: str, rpc: str, request, *, started: bool = False,
              timeout: float | None = None):
        return self._invoke(service, rpc, request, started, timeout)
