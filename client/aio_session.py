"""The asyncio twin of `Session`: a client's session over a `grpc.aio` channel.

    async with grpc.aio.insecure_channel(target) as channel:
        async with AsyncSession(channel, "cell-supervisor") as session:
            await session.lock()
            device = DeviceServiceStub(channel)
            await device.Activate(ActivateRequest(), metadata=session.metadata())

Keep-alives run as a task on the caller's event loop; RSVP questions go to `on_rsvp` (a plain
or async function returning (choice, data), or None to leave one unanswered), or wait
unanswered for the device's default.
"""
from __future__ import annotations

import asyncio
import inspect
from typing import Awaitable, Callable

import grpc

from landscape.client.session import LEASE_KEY
from landscape.v1 import control_pb2, device_service_pb2_grpc, event_service_pb2
from landscape.v1 import session_service_pb2 as pb
from landscape.v1 import session_service_pb2_grpc

AsyncRsvpHandler = Callable[[event_service_pb2.RsvpRequest],
                            "tuple[str, list[str]] | None | Awaitable[tuple[str, list[str]] | None]"]


class AsyncSession:
    """One session on a grpc.aio channel: opened on enter, closed on exit (the device then runs
    its disconnect handler if this session held the lock)."""

    def __init__(self, channel: grpc.aio.Channel, client_name: str,
                 on_rsvp: AsyncRsvpHandler | None = None):
        self.channel = channel
        self.client_name = client_name
        self.on_rsvp = on_rsvp
        self.session_id = ""
        self.session_secret = ""
        self.lease: str | None = None
        self.rsvp_requests: asyncio.Queue = asyncio.Queue()   # every question asked
        self.ended = asyncio.Event()
        self.end_status: grpc.StatusCode | None = None   # why the server ended it, if it did
        self._outgoing: asyncio.Queue = asyncio.Queue()
        self._tasks: list[asyncio.Task] = []
        self._call = None

    async def __aenter__(self) -> "AsyncSession":
        return await self.open()

    async def __aexit__(self, *exc) -> None:
        await self.close()

    async def open(self, timeout: float = 10.0) -> "AsyncSession":
        stub = session_service_pb2_grpc.SessionServiceStub(self.channel)
        await self._outgoing.put(pb.ConnectRequest(hello=pb.Hello(client_name=self.client_name)))
        self._call = stub.Connect(self._requests())
        first = await asyncio.wait_for(self._call.read(), timeout)
        if first is grpc.aio.EOF:
            raise ConnectionError("the device server closed the session at once")
        opened = first.opened
        self.session_id, self.session_secret = opened.session_id, opened.session_secret
        interval = opened.keepalive_interval_ms / 1000.0
        self._tasks = [asyncio.create_task(self._keep_alive(interval)),
                       asyncio.create_task(self._read())]
        return self

    async def close(self) -> None:
        for task in self._tasks:
            task.cancel()
        if self._call is not None:
            self._call.cancel()
        self.ended.set()

    async def lock(self, timeout: float = 10.0) -> str:
        """Take the lock for this session; returns the lease (also kept for `metadata()`)."""
        stub = device_service_pb2_grpc.DeviceServiceStub(self.channel)
        reply = await stub.Lock(control_pb2.LockRequest(
            session_id=self.session_id, session_secret=self.session_secret), timeout=timeout)
        self.lease = reply.lease
        return self.lease

    def metadata(self) -> tuple[tuple[str, str], ...]:
        """The call metadata that carries the lease (empty before `lock`)."""
        return ((LEASE_KEY, self.lease),) if self.lease else ()

    async def _requests(self):
        while (item := await self._outgoing.get()) is not None:
            yield item

    async def _keep_alive(self, interval: float) -> None:
        counter = 0
        while True:
            await asyncio.sleep(interval)
            counter += 1
            await self._outgoing.put(pb.ConnectRequest(keep_alive=pb.KeepAlive(counter=counter)))

    async def _read(self) -> None:
        # read(), as open() did: grpc.aio refuses iterating a call that was read from.
        try:
            while (message := await self._call.read()) is not grpc.aio.EOF:
                if message.WhichOneof("message") == "rsvp_request":
                    await self._answer(message.rsvp_request)
        except grpc.aio.AioRpcError as error:
            self.end_status = error.code()
        except asyncio.CancelledError:
            pass
        finally:
            self.ended.set()

    async def _answer(self, request) -> None:
        await self.rsvp_requests.put(request)
        if self.on_rsvp is None:
            return   # unanswered: the device takes its default when the time is up
        answer = self.on_rsvp(request)
        answer = await answer if inspect.isawaitable(answer) else answer
        if answer is None:
            return   # left to the device's timeout
        choice, data = answer
        await self._outgoing.put(pb.ConnectRequest(rsvp_answer=event_service_pb2.RsvpAnswer(
            rsvp_id=request.rsvp_id, choice=choice, data=data)))
