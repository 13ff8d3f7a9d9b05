"""A session's Connect stream on the loop of a grpc.aio channel the caller opened itself.

The client core's own sessions run on a Keeper's threads (keeper.py); a program that hands
AsyncSession its own grpc.aio channel gets this instead: the stream and its keep-alives are
tasks on that channel's loop, which must stay free for them (a computation that holds the loop
past the device's keep-alive timeout loses the session). A refusal at once may read as
INTERNAL here (grpc/grpc#36066, see keeper.py).
"""
from __future__ import annotations

import asyncio

import grpc

from landscape.v1 import control_pb2, device_service_pb2_grpc
from landscape.v1 import session_service_pb2 as pb
from landscape.v1 import session_service_pb2_grpc


class LoopStream:
    """As keeper.ThreadStream: `opened`, `send`, `cancel`; and `lock` on the same channel."""

    def __init__(self, channel: grpc.aio.Channel, hello: pb.ConnectRequest, metadata,
                 on_message, on_end):
        self._channel = channel
        self.opened: asyncio.Future = asyncio.get_running_loop().create_future()
        self._outgoing: asyncio.Queue = asyncio.Queue()
        self._outgoing.put_nowait(hello)
        self._call = session_service_pb2_grpc.SessionServiceStub(channel).Connect(
            _requests(self._outgoing), metadata=tuple(metadata))
        self._task = asyncio.ensure_future(self._read(on_message, on_end))

    def send(self, request: pb.ConnectRequest) -> None:
        self._outgoing.put_nowait(request)

    def cancel(self) -> None:
        self._call.cancel()

    async def lock(self, request: control_pb2.LockRequest, metadata,
                   timeout: float) -> control_pb2.LockResponse:
        return await device_service_pb2_grpc.DeviceServiceStub(self._channel).Lock(
            request, metadata=metadata, timeout=timeout)

    async def _read(self, on_message, on_end) -> None:
        sender = None
        try:
            first = await self._call.read()
            if first is grpc.aio.EOF:
                raise ConnectionError("the device server closed the session at once")
            self.opened.set_result(first.opened)
            sender = asyncio.ensure_future(_keep_alive(
                self._outgoing, first.opened.keepalive_interval_ms / 1e3))
            while (message := await self._call.read()) is not grpc.aio.EOF:
                on_message(message)
            code, details = grpc.StatusCode.OK, "the device server closed it"
        except (grpc.aio.AioRpcError, ConnectionError) as error:
            code, details = ((error.code(), error.details() or error.code().name)
                             if isinstance(error, grpc.aio.AioRpcError)
                             else (grpc.StatusCode.UNKNOWN, str(error)))
            if not self.opened.done():
                self.opened.set_exception(error)
        except asyncio.CancelledError:          # cancel(): this client closed it
            code, details = grpc.StatusCode.CANCELLED, "closed by this client"
            if not self.opened.done():
                self.opened.set_exception(ConnectionError("closed while opening"))
        finally:
            if sender is not None:
                sender.cancel()
            self._outgoing.put_nowait(None)     # the request stream ends: grpc's task with it
        on_end(code, details)


async def _requests(outgoing: asyncio.Queue):
    while (item := await outgoing.get()) is not None:
        yield item


async def _keep_alive(outgoing: asyncio.Queue, interval: float) -> None:
    counter = 0
    while True:
        await asyncio.sleep(interval)
        counter += 1
        outgoing.put_nowait(pb.ConnectRequest(keep_alive=pb.KeepAlive(counter=counter)))
