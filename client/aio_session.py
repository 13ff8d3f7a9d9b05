"""A client's session with a device server, for asyncio programs: the Connect stream and its
keep-alives, the lock's lease, the device's RSVP questions, and the session's end.

    link = DeviceLink(Endpoint("127.0.0.1:50051"), Identity("cell-supervisor"))
    await link.open()
    async with link.session("cell-supervisor") as session:
        await session.lock()
        device = DeviceServiceStub(link.channel)
        await device.Activate(ActivateRequest(), metadata=session.metadata())

The stream runs on a Keeper's threads (keeper.py), so the keep-alives go out however busy the
caller's loop is. Given a grpc.aio channel instead (the caller's own), the stream runs on that
channel's loop (loop_stream.py), which must then stay free.

When the device ends the session (no keep-alive arrived in time, the server stopped), `ended`
is set, `lost` says why in the device's words (errors.SessionEnded), and the end listeners are
called on the caller's loop: the device has stopped the arm and freed the lock, and nothing
here takes it back. RSVP questions go to `on_rsvp` (a plain or async function returning
(choice, data), or None to leave one unanswered), or wait unanswered for the device's default.
"""
from __future__ import annotations

import asyncio
import inspect
import logging
from typing import Awaitable, Callable

import grpc

from landscape.client.credentials import bearer
from landscape.client.errors import SessionEnded
from landscape.client.identity import Identity
from landscape.client.keeper import Keeper
from landscape.client.loop_stream import LoopStream
from landscape.v1 import control_pb2, event_service_pb2
from landscape.v1 import session_service_pb2 as pb

log = logging.getLogger(__name__)

LEASE_KEY = "landscape-lease"

AsyncRsvpHandler = Callable[[event_service_pb2.RsvpRequest],
                            "tuple[str, list[str]] | None | Awaitable[tuple[str, list[str]] | None]"]
EndListener = Callable[["SessionEnded | None"], None]


class AsyncSession:
    """One session: opened by `open` (or `async with`), closed by `close` (the device then runs
    its disconnect handler if it held the lock). `device` is a Keeper (a program's: see
    DeviceLink.session) or a grpc.aio channel of the caller's. identity: who calls, for the
    device's records; token: the role token this session's calls present, for a program that
    calls for several people on one channel opened without one."""

    def __init__(self, device: Keeper | grpc.aio.Channel, client_name: str,
                 on_rsvp: AsyncRsvpHandler | None = None, *, identity: Identity | None = None,
                 token: str | None = None):
        self._device = device
        self.client_name = client_name
        self.on_rsvp = on_rsvp
        self.identity = identity or Identity(client_name)
        self._caller = (*self.identity.metadata(), *bearer(token))   # on every call
        self.session_id = ""
        self.session_secret = ""
        self.lease: str | None = None
        self.rsvp_requests: asyncio.Queue = asyncio.Queue()   # every question asked
        self.ended = asyncio.Event()
        self.end_status: grpc.StatusCode | None = None   # how the stream ended
        self.end_details = ""
        self.lost: SessionEnded | None = None   # why the device ended it, if it did
        self._listeners: list[EndListener] = []
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stream = None
        self._closing = False

    async def __aenter__(self) -> "AsyncSession":
        return await self.open()

    async def __aexit__(self, *exc) -> None:
        await self.close()

    async def open(self, timeout: float = 10.0) -> "AsyncSession":
        """Open the stream; raises the call's grpc.RpcError if the device refuses."""
        self._loop = asyncio.get_running_loop()
        hello = pb.ConnectRequest(hello=pb.Hello(client_name=self.client_name))
        make = self._device.stream if isinstance(self._device, Keeper) else self._on_loop
        self._stream = make(hello, self._caller, self._message, self._end)
        try:
            async with asyncio.timeout(timeout):
                opened = await asyncio.wrap_future(self._stream.opened)
        except BaseException:
            self._closing = True
            self._stream.cancel()
            raise
        self.session_id, self.session_secret = opened.session_id, opened.session_secret
        return self

    def _on_loop(self, *args) -> LoopStream:
        return LoopStream(self._device, *args)

    async def close(self, timeout: float = 5.0) -> None:
        """End the session (the device stops, deactivates and releases if it held the lock)."""
        self._closing = True
        if self._stream is not None and not self.ended.is_set():
            self._stream.cancel()
            try:
                async with asyncio.timeout(timeout):
                    await self.ended.wait()
            except TimeoutError:
                log.warning("session %s: its stream did not end in %g s", self.session_id,
                            timeout)
        self.ended.set()

    async def lock(self, timeout: float = 10.0) -> str:
        """Take the lock for this session; returns the lease (also kept for `metadata()`).
        A session the device ended raises SessionEnded: the lock is never taken back by
        itself, a new session must ask for it. A refusal is the call's grpc.RpcError."""
        if self.lost is not None:
            raise self.lost
        request = control_pb2.LockRequest(session_id=self.session_id,
                                          session_secret=self.session_secret)
        if isinstance(self._device, Keeper):
            reply = await asyncio.to_thread(self._device.lock, request, self._caller, timeout)
        else:
            reply = await self._stream.lock(request, self._caller, timeout)
        self.lease = reply.lease
        return self.lease

    def released(self) -> None:
        """The lock was handed back (Release): the lease is void."""
        self.lease = None

    def metadata(self) -> tuple[tuple[str, str], ...]:
        """What every call of this session carries: who calls (identity.py), its token if it
        has its own, and the lease once locked."""
        return (*self._caller, *(((LEASE_KEY, self.lease),) if self.lease else ()))

    def add_end_listener(self, listener: EndListener) -> None:
        """`listener(lost)` is called on this loop when the session ends (lost: None when this
        client closed it); at once if it has ended."""
        if self.ended.is_set():
            listener(self.lost)
        else:
            self._listeners.append(listener)

    async def loss(self, grace: float) -> SessionEnded | None:
        """Why the device ended the session, waiting up to `grace` s for the stream to say so
        (the device has ended it when it says the lock holder is gone); None if it did not."""
        if not self.ended.is_set():
            try:
                async with asyncio.timeout(grace):
                    await self.ended.wait()
            except TimeoutError:
                pass
        return self.lost

    # ---- from the stream (any thread) ------------------------------------------------------

    def _message(self, message: pb.ConnectResponse) -> None:
        if message.WhichOneof("message") == "rsvp_request":
            self._to_caller(self._asked, message.rsvp_request)

    def _end(self, code: grpc.StatusCode, details: str) -> None:
        self._to_caller(self._ended, code, details)

    def _to_caller(self, callback, *args) -> None:
        try:
            self._loop.call_soon_threadsafe(callback, *args)
        except RuntimeError:     # the caller's loop is closed: nobody is left to tell
            pass

    # ---- on the caller's loop ------------------------------------------------------------

    def _ended(self, code: grpc.StatusCode, details: str) -> None:
        self.end_status, self.end_details = code, details
        held = self.lease is not None
        self.lease = None
        if not self._closing:
            self.lost = SessionEnded(details, code, held)
            log.info("session %s (%s) ended by the device: %s", self.session_id,
                     self.client_name, details)
        self.ended.set()
        listeners, self._listeners = self._listeners, []
        for listener in listeners:
            listener(self.lost)

    def _asked(self, request: event_service_pb2.RsvpRequest) -> None:
        self.rsvp_requests.put_nowait(request)
        if self.on_rsvp is not None:
            asyncio.ensure_future(self._answer(request))

    async def _answer(self, request: event_service_pb2.RsvpRequest) -> None:
        answer = self.on_rsvp(request)
        answer = await answer if inspect.isawaitable(answer) else answer
        if answer is None or self.ended.is_set():
            return   # left to the device's timeout
        choice, data = answer
        self._stream.send(pb.ConnectRequest(rsvp_answer=event_service_pb2.RsvpAnswer(
            rsvp_id=request.rsvp_id, choice=choice, data=data)))
