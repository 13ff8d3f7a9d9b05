"""A client's session with a device server, for asyncio programs: the Connect stream and its
keep-alives, the lock's lease, the device's RSVP questions, and the session's end.

    link = DeviceLink(Endpoint("127.0.0.1:50051"), Identity("cell-supervisor"))
    await link.open()
    async with link.session("cell-supervisor") as session:
        await session.lock()
        device = DeviceServiceStub(link.channel)
        await device.Activate(ActivateRequest(), metadata=session.metadata())

The stream runs on a Keeper (keeper.py): a loop and a channel of its own, so the keep-alives go
out however busy the caller's loop is. Given a grpc.aio channel instead (the caller's own),
the stream runs on that channel's loop, which must then stay free.

When the device ends the session (no keep-alive arrived in time, the server stopped), `ended`
is set, `lost` says why in the device's words (errors.SessionEnded), and the end listeners are
called on the caller's loop: the device has stopped the arm and freed the lock, and nothing
here takes it back. RSVP questions go to `on_rsvp` (a plain or async function returning
(choice, data), or None to leave one unanswered), or wait unanswered for the device's default.
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import inspect
import logging
from typing import Awaitable, Callable

import grpc

from landscape.client.credentials import bearer
from landscape.client.errors import SessionEnded
from landscape.client.identity import Identity
from landscape.client.keeper import Keeper
from landscape.v1 import control_pb2, device_service_pb2_grpc, event_service_pb2
from landscape.v1 import session_service_pb2 as pb
from landscape.v1 import session_service_pb2_grpc

log = logging.getLogger(__name__)

LEASE_KEY = "landscape-lease"
CLOSED_BY_CLIENT = "closed by this client"

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
        self._keeper: Keeper | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._stream: concurrent.futures.Future | None = None
        self._outgoing: asyncio.Queue | None = None   # on the keeper's loop
        self._lapsed = False       # the keeper stalled past the device's keep-alive timeout
        self._closing = False

    async def __aenter__(self) -> "AsyncSession":
        return await self.open()

    async def __aexit__(self, *exc) -> None:
        await self.close()

    # ---- the caller's side ----------------------------------------------------------------

    async def open(self, timeout: float = 10.0) -> "AsyncSession":
        """Open the stream; raises the call's grpc.aio.AioRpcError if the device refuses."""
        self._loop = asyncio.get_running_loop()
        self._keeper = self._device if isinstance(self._device, Keeper) else Keeper.on(
            self._device)
        opened: concurrent.futures.Future = concurrent.futures.Future()
        self._stream = self._keeper.submit(self._run(opened, timeout))
        reply = await asyncio.wrap_future(opened)
        self.session_id, self.session_secret = reply.session_id, reply.session_secret
        return self

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
        itself, a new session must ask for it."""
        if self.lost is not None:
            raise self.lost
        reply = await self._keeper.run(self._lock(timeout))
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
        self._keeper.call_soon(self._send, pb.ConnectRequest(
            rsvp_answer=event_service_pb2.RsvpAnswer(rsvp_id=request.rsvp_id, choice=choice,
                                                     data=data)))

    def _to_caller(self, callback, *args) -> None:
        try:
            self._loop.call_soon_threadsafe(callback, *args)
        except RuntimeError:     # the caller's loop is closed: nobody is left to tell
            pass

    # ---- the keeper's side: the stream ----------------------------------------------------

    async def _run(self, opened: concurrent.futures.Future, timeout: float) -> None:
        self._outgoing = asyncio.Queue()
        self._outgoing.put_nowait(pb.ConnectRequest(hello=pb.Hello(client_name=self.client_name)))
        stub = session_service_pb2_grpc.SessionServiceStub(self._keeper.channel)
        call = stub.Connect(self._requests(), metadata=self._caller)
        try:
            async with asyncio.timeout(timeout):
                first = await call.read()
            if first is grpc.aio.EOF:
                raise ConnectionError("the device server closed the session at once")
        except BaseException as error:
            self._outgoing.put_nowait(None)
            call.cancel()
            opened.set_exception(error if isinstance(error, Exception) else ConnectionError(
                "the session was closed while opening"))
            return
        opened.set_result(first.opened)
        sender = asyncio.create_task(self._keep_alive(first.opened.keepalive_interval_ms / 1e3,
                                                      first.opened.keepalive_timeout_ms / 1e3))
        code, details = grpc.StatusCode.OK, "the device server closed it"
        try:
            while (message := await call.read()) is not grpc.aio.EOF:
                if message.WhichOneof("message") == "rsvp_request":
                    self._to_caller(self._asked, message.rsvp_request)
        except grpc.aio.AioRpcError as error:
            code, details = error.code(), error.details() or error.code().name
        except asyncio.CancelledError:
            code, details = grpc.StatusCode.CANCELLED, CLOSED_BY_CLIENT
        finally:
            sender.cancel()
            self._outgoing.put_nowait(None)    # the request stream ends: grpc's task with it
            call.cancel()
            self._to_caller(self._ended, code, details)

    async def _lock(self, timeout: float) -> control_pb2.LockResponse:
        stub = device_service_pb2_grpc.DeviceServiceStub(self._keeper.channel)
        return await stub.Lock(control_pb2.LockRequest(
            session_id=self.session_id, session_secret=self.session_secret),
            metadata=self._caller, timeout=timeout)

    async def _requests(self):
        while (item := await self._outgoing.get()) is not None:
            yield item

    async def _keep_alive(self, interval: float, timeout: float) -> None:
        """A keep-alive every `interval` s. If this thread was held up past the device's
        `timeout` (the whole process stopped, the machine suspended), the device has ended the
        session: nothing more is sent, and the stream's end says why (a write after the
        device's status would hide it: grpc.aio reports it as INTERNAL, grpc/grpc#36066)."""
        loop = asyncio.get_running_loop()
        counter, last = 0, loop.time()
        while True:
            await asyncio.sleep(interval)
            if loop.time() - last >= timeout:
                self._lapsed = True
                log.info("session %s: no keep-alive could go out for %.1f s", self.session_id,
                         loop.time() - last)
                return
            last = loop.time()
            counter += 1
            self._send(pb.ConnectRequest(keep_alive=pb.KeepAlive(counter=counter)))

    def _send(self, request: pb.ConnectRequest) -> None:
        if not self._lapsed:
            self._outgoing.put_nowait(request)
