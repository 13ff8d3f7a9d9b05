"""`AsyncRobot`: one device server for asyncio programs, the client core every front end uses.

    async with AsyncRobot("127.0.0.1:50051", "my-program") as robot:   # or tls=, token=
        async with robot.control():
            move = await robot.move_absolute([0.5, 0, 1.57, 0, 1.57, 0], Frame.JOINT)
            await move.wait(timeout=30)
        async for event in robot.events():
            ...

The command methods are in commands.py; here each returns an awaitable. A robot is a session
(aio_session.py) on a DeviceLink (link.py): its own link for a "host:port" or Endpoint, or a
link the program shares among many robots (the gateway's CRCL connections each have one; a
supervisor's people, one per person, each reading before `open()` adds its session).
Must be used from one event loop. If the device ends the session (errors.SessionEnded: it
stopped the arm and freed the lock), the command waited for and every later call that needed
the lock raise it with the device's reason; `lock()` raises it too: a program that wants the
lock back opens a new AsyncRobot.
"""
from __future__ import annotations

import contextlib
import logging
from dataclasses import dataclass, field
from typing import AsyncIterable, AsyncIterator, Sequence

import grpc

from landscape.client.aio_session import AsyncRsvpHandler, AsyncSession
from landscape.client.aio_streams import (AsyncEventStream, AsyncStateStream, state_request,
                                          subscribe_request)
from landscape.client.commands import (DEVICE, EVENTS, IO, RELINQUISH_MAX_STEPS,
                                       RELINQUISH_STEP, DeviceCommands, jog_request)
from landscape.client.credentials import ClientTLS, Endpoint, bearer
from landscape.client.errors import (CommandRefused, NotAllowed, NotLockHolder, SessionEnded,
                                     WrongState, from_rpc_error)
from landscape.client.event_feed import LOSS_GRACE, EventFeed
from landscape.client.identity import Identity
from landscape.client.link import DeviceLink
from landscape.client.values import DeviceState, Frame
from landscape.v1 import (audit_service_pb2_grpc, device_service_pb2_grpc,
                          digital_io_service_pb2_grpc, event_service_pb2, event_service_pb2_grpc,
                          recording_service_pb2_grpc, sensing_pb2, state_service_pb2,
                          state_service_pb2_grpc, types_pb2)

log = logging.getLogger(__name__)

DEFAULT_TIMEOUT = 30.0   # seconds, for a blocking call that names none
# The stubs beside commands.DEVICE, IO, EVENTS: for streams and invoke_stream.
STATE, RECORDING, AUDIT = "state", "recording", "audit"
FENCE_TIMEOUT = 5.0      # seconds for the event subscription to be registered (event_feed.py)


@dataclass
class AsyncCommand:
    """A started non-blocking command: its id (named by its events) and the reply's RetVal."""
    command_id: str
    command: str
    ret_val: types_pb2.RetVal
    _feed: EventFeed = field(repr=False)
    _session: AsyncSession | None = field(repr=False, default=None)

    async def wait(self, timeout: float | None = 60.0) -> event_service_pb2.Event:
        """Its done event; raises CommandFailed (with the alarm) / CommandAborted when it ends
        otherwise, SessionEnded if its session was lost, CommandTimeout after `timeout` s."""
        return await self._feed.wait(self.command_id, timeout, self._session)

    def follow(self, timeout: float | None = 60.0) -> AsyncIterator[event_service_pb2.Event]:
        """`async for` each of its events, ending with the done event (raises as `wait`)."""
        return self._feed.follow(self.command_id, timeout, self._session)

    @property
    def events(self) -> list[event_service_pb2.Event]:
        return self._feed.events(self.command_id)


class AsyncRobot(DeviceCommands):
    """target: "host:port" (with `tls` and `token`), an Endpoint, an open grpc.aio.Channel (the
    caller closes it; the session's keep-alives then share its loop), or a DeviceLink shared
    with other robots (opened and closed by its owner; `token` is then this robot's own, on
    each of its calls: a person's, on a link opened without one). client_name: shown to other
    clients as the lock holder. identity: who calls, for the device's records (identity.py;
    default: client_name for itself). on_rsvp: answers the device's RSVP questions (a plain or
    async function; see AsyncSession)."""

    def __init__(self, target: str | Endpoint | grpc.aio.Channel | DeviceLink,
                 client_name: str = "landscape-client", *,
                 on_rsvp: AsyncRsvpHandler | None = None, tls: ClientTLS | None = None,
                 token: str | None = None, identity: Identity | None = None):
        shared = isinstance(target, DeviceLink)
        if not isinstance(target, str) and (tls is not None or token and not shared):
            raise ValueError("TLS and the token belong to the channel: give them to "
                             "open_aio_channel, or give AsyncRobot a \"host:port\"")
        self.client_name = client_name
        self.identity = identity or Identity(client_name)
        self._token = token if shared else None       # presented per call, on a shared link
        self._own_link = not shared
        if isinstance(target, str):
            target = Endpoint(target, tls, token)
        self._link = target if not self._own_link else DeviceLink(target, self.identity)
        self.target = self._link.target
        self._on_rsvp = on_rsvp
        self._session: AsyncSession | None = None
        self._no_session: NotAllowed | None = None   # why there is no session, if refused
        self._stubs: dict | None = None               # made on first use (_stub)

    async def open(self, timeout: float = 10.0) -> "AsyncRobot":
        """The link (if this robot's own) and the session; a role token that may not open a
        session (a viewer's) leaves the robot to reads and streams. Once open, opening again
        does nothing."""
        if self._session is not None or self._no_session is not None:
            return self
        if self._own_link:
            await self._link.open(timeout)
        session = self._link.session(self.client_name, self._on_rsvp, identity=self.identity,
                                     token=self._token)
        try:
            self._session = await session.open(timeout)
        except grpc.RpcError as error:
            refused = from_rpc_error(error, "Connect")
            if not isinstance(refused, NotAllowed):
                await self.close()
                raise refused from None
            self._no_session = refused
        return self

    async def close(self) -> None:
        """End the session (the device releases the lock if it was held), and the link if it
        is this robot's own."""
        if self._session is not None:
            await self._session.close()
        if self._own_link:
            await self._link.close()

    async def __aenter__(self) -> "AsyncRobot":
        return await self.open()

    async def __aexit__(self, *exc) -> None:
        await self.close()

    @property
    def session(self) -> AsyncSession | None:
        """The session (session_id, lease, ended, lost); None when the role token may not open
        one (a viewer's: reads and streams only)."""
        return self._session

    @property
    def lost(self) -> SessionEnded | None:
        """Why the device ended this robot's session, if it did."""
        return self._session.lost if self._session is not None else None

    # ---- the lock ----

    async def lock(self, timeout: float = 10.0) -> str:
        """Seed 3.1.1: take the lock for this session; returns the lease, which every later
        call carries. SessionEnded if the device ended the session."""
        if self._session is None:
            raise self._no_session or WrongState(
                "open a session first: the lock belongs to a session",
                grpc.StatusCode.FAILED_PRECONDITION, rpc="Lock")
        await self._link.events.ready(FENCE_TIMEOUT)   # its commands' events will be seen
        try:
            return await self._session.lock(timeout)
        except grpc.RpcError as error:
            raise from_rpc_error(error, "Lock") from None

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
        """Stop, abort, deactivate and release as the state needs; returns the state reached.
        After a lost session there is nothing to hand back: the device did it."""
        state = DeviceState.UNLOCKED
        for _ in range(RELINQUISH_MAX_STEPS):
            if self.lost is not None:
                return state
            state = DeviceState((await self.get_device_state()).state)
            step = RELINQUISH_STEP.get(state)
            if step is None:
                return state
            try:
                await getattr(self, step)()
            except (NotLockHolder, NotAllowed, SessionEnded):   # not (or no longer) ours
                return state
            except CommandRefused as refused:   # the state moved on by itself: look again
                log.debug("relinquish: %s refused: %s", step, refused)
        return state

    # ---- streams ----

    def event_stream(self, after_sequence: int | None = None,
                     timeout: float | None = None) -> AsyncEventStream:
        """Events and alarms (seed 2.1): live only, or the kept ones after `after_sequence`
        first; with `timeout` (s) the stream raises RpcTimeout when that time is up."""
        return AsyncEventStream(self._stub(EVENTS).Subscribe(
            subscribe_request(after_sequence), metadata=self._metadata(), timeout=timeout))

    async def events(self, after_sequence: int | None = None, timeout: float | None = None
                     ) -> AsyncIterator[event_service_pb2.Event]:
        """`async for` events and alarms (see event_stream)."""
        async with self.event_stream(after_sequence, timeout) as stream:
            async for event in stream:
                yield event

    def state_stream(self, rate_hz: float = 10.0, frame: Frame | None = None,
                     units: types_pb2.Units | None = None, sensors: Sequence[str] = (),
                     timeout: float | None = None) -> AsyncStateStream:
        """The device's state at `rate_hz` samples per second (0: every 4 ms cycle); see
        state_service.proto."""
        return AsyncStateStream(self._stub(STATE).StreamState(
            state_request(rate_hz, frame, units, sensors), metadata=self._metadata(),
            timeout=timeout))

    async def live_state(self, rate_hz: float = 10.0, frame: Frame | None = None,
                         units: types_pb2.Units | None = None, sensors: Sequence[str] = (),
                         timeout: float | None = None
                         ) -> AsyncIterator[state_service_pb2.StateSample]:
        """`async for` state samples (see state_stream)."""
        async with self.state_stream(rate_hz, frame, units, sensors, timeout) as stream:
            async for sample in stream:
                yield sample

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

        async for reply in self.jog_stream(requests()):
            yield reply

    async def jog_stream(self, requests: AsyncIterable[sensing_pb2.JogRequest]
                         ) -> AsyncIterator[sensing_pb2.JogResponse]:
        """`async for` a JogResponse per message of one Jog stream, whose JogRequests the
        caller makes and paces (a program relaying someone's jog: each button press its own
        stream); the stream ends when `requests` does."""
        async for reply in self.invoke_stream(DEVICE, "Jog", requests):
            yield reply

    async def invoke_stream(self, service: str, rpc: str, request,
                            timeout: float | None = None) -> AsyncIterator:
        """`async for` each reply of a streaming call of the contract (GetPath; Jog, whose
        `request` is an async iterable of requests); the client's exceptions when it fails;
        with `timeout` (s) the whole stream must end within it."""
        call = getattr(self._stub(service), rpc)(request, metadata=self._metadata(),
                                                  timeout=timeout)
        try:
            async for reply in call:
                yield reply
        except grpc.aio.AioRpcError as error:
            raise await self._refusal(error, rpc) from None
        finally:
            call.cancel()

    # ---- every command goes through here ----

    def _stub(self, service: str):
        """The service's stub on the link's channel, made on first use: a robot on a shared
        link reads and streams before (or without) its session."""
        if self._stubs is None:
            channel = self._link.channel
            if channel is None:
                raise RuntimeError(f"{self.target}: open the robot (or its link) first")
            self._stubs = {DEVICE: device_service_pb2_grpc.DeviceServiceStub(channel),
                           IO: digital_io_service_pb2_grpc.DigitalIOServiceStub(channel),
                           EVENTS: event_service_pb2_grpc.EventServiceStub(channel),
                           STATE: state_service_pb2_grpc.StateServiceStub(channel),
                           RECORDING: recording_service_pb2_grpc.RecordingServiceStub(channel),
                           AUDIT: audit_service_pb2_grpc.AuditServiceStub(channel)}
        return self._stubs[service]

    def _metadata(self) -> tuple[tuple[str, str], ...]:
        return self._session.metadata() if self._session else (
            *self.identity.metadata(), *bearer(self._token))

    async def invoke(self, service: str, rpc: str, request, started: bool = False,
                     timeout: float | None = None):
        """One call of the contract: the reply, or for a started command an AsyncCommand;
        the client's exceptions when it fails (errors.py)."""
        if started:
            await self._link.events.ready(FENCE_TIMEOUT)
        try:
            reply = await getattr(self._stub(service), rpc)(
                request, metadata=self._metadata(), timeout=timeout or DEFAULT_TIMEOUT)
        except grpc.aio.AioRpcError as error:
            raise await self._refusal(error, rpc) from None
        if rpc == "Release" and self._session is not None:
            self._session.released()
        if started:
            return AsyncCommand(reply.ret_val.command_id, rpc, reply.ret_val, self._link.events,
                                self._session)
        return reply

    async def _refusal(self, error: grpc.aio.AioRpcError, rpc: str) -> Exception:
        """The client's exception for a failed call. Refused for want of the lock (or in a
        state the loss left), after the device ended this session: the loss, in the device's
        words; for want of the lock while this session held it: the loss, once its stream
        says why (the device ends the session before it lets the lock go)."""
        refused = from_rpc_error(error, rpc)
        session = self._session
        if session is None or not isinstance(refused, (NotLockHolder, WrongState)):
            return refused
        if session.lost is None and isinstance(refused, NotLockHolder) and session.lease:
            await session.loss(LOSS_GRACE)
        return session.lost or refused

    def _call(self, service: str, rpc: str, request, *, started: bool = False,
              timeout: float | None = None):
        return self.invoke(service, rpc, request, started, timeout)
