"""Where a program's session streams live: on threads of their own, over a channel of their own.

A session's keep-alives must reach the device every interval it asks for (it ends the session,
stopping the arm and freeing the lock, after a few missed ones), whatever the program does
meanwhile: a long computation on its event loop, a blocking call, a slow callback. So the
session streams do not run on the caller's loop. A `Keeper` holds a synchronous channel to the
device for them; each stream (`ThreadStream`) has a reader thread, and gRPC's own thread sends
what the stream's request generator yields: the hello, the keep-alives it makes when nothing
else is sent for an interval, RSVP answers. Nothing else runs there.

Why gRPC's synchronous API here: grpc.aio reports a stream the server refused at once (a bad
token, a server without the service) as INTERNAL when the first message's write loses the
race with the refusal (grpc/grpc#36066); the synchronous API reports the server's status.

A stream whose threads were held up past the device's keep-alive timeout (the process
stopped, the machine suspended) sends nothing more: the device has ended the session, and the
stream's end says why.
"""
from __future__ import annotations

import concurrent.futures
import logging
import queue
import threading
import time
from typing import Callable

import grpc

from landscape.client.credentials import open_channel
from landscape.v1 import control_pb2, device_service_pb2_grpc
from landscape.v1 import session_service_pb2 as pb
from landscape.v1 import session_service_pb2_grpc

log = logging.getLogger(__name__)

_END = None          # the request stream's last item
_TIMED = object()    # wakes the request stream: the keep-alive timing is known


class Keeper:
    """The channel a program's session streams use (one per device the program talks to)."""

    def __init__(self, channel: grpc.Channel):
        self.channel = channel

    @classmethod
    def start(cls, endpoint) -> "Keeper":
        """A channel from `endpoint` (credentials.Endpoint): its TLS and token."""
        return cls(open_channel(endpoint.target, endpoint.tls, endpoint.token))

    def stream(self, hello: pb.ConnectRequest, metadata,
               on_message: Callable[[pb.ConnectResponse], None],
               on_end: Callable[[grpc.StatusCode, str], None]) -> "ThreadStream":
        return ThreadStream(self.channel, hello, metadata, on_message, on_end)

    def lock(self, request: control_pb2.LockRequest, metadata,
             timeout: float) -> control_pb2.LockResponse:
        """Lock (blocking): it proves the session's secret, on the session's own channel."""
        return device_service_pb2_grpc.DeviceServiceStub(self.channel).Lock(
            request, metadata=metadata, timeout=timeout)

    def close(self) -> None:
        self.channel.close()


class ThreadStream:
    """One session's Connect stream on threads. `on_message(response)` is called for each
    message after the first (SessionOpened, which `opened` holds), `on_end(code, details)`
    once, on the reader thread."""

    def __init__(self, channel: grpc.Channel, hello: pb.ConnectRequest, metadata,
                 on_message, on_end):
        self.opened: concurrent.futures.Future = concurrent.futures.Future()
        self._outgoing: queue.Queue = queue.Queue()
        self._outgoing.put(hello)
        self._on_message, self._on_end = on_message, on_end
        self._timing = (None, None)          # keep-alive interval and timeout, once opened
        self._call = session_service_pb2_grpc.SessionServiceStub(channel).Connect(
            self._requests(), metadata=tuple(metadata))
        threading.Thread(target=self._read, daemon=True, name="landscape-session").start()

    def send(self, request: pb.ConnectRequest) -> None:
        self._outgoing.put(request)

    def cancel(self) -> None:
        self._call.cancel()

    def _read(self) -> None:
        try:
            first = next(self._call)
            opened = first.opened
            self._timing = (opened.keepalive_interval_ms / 1e3, opened.keepalive_timeout_ms / 1e3)
            self._outgoing.put(_TIMED)
            self.opened.set_result(opened)
            for message in self._call:
                self._on_message(message)
            code, details = grpc.StatusCode.OK, "the device server closed it"
        except grpc.RpcError as error:
            code, details = error.code(), error.details() or error.code().name
            if not self.opened.done():
                self.opened.set_exception(error)
        except StopIteration:
            code, details = grpc.StatusCode.UNKNOWN, "the device server closed the session at once"
            self.opened.set_exception(ConnectionError(details))
        finally:
            self._outgoing.put(_END)
        self._on_end(code, details)

    def _requests(self):
        """The hello, then what is sent, and a keep-alive whenever nothing was for an interval;
        nothing more once the thread was held up past the device's timeout."""
        counter, last = 0, time.monotonic()
        while True:
            interval, timeout = self._timing
            try:
                item = self._outgoing.get(timeout=interval)
            except queue.Empty:
                if time.monotonic() - last >= timeout:
                    log.info("no keep-alive could go out for %.1f s: the device has ended the "
                             "session", time.monotonic() - last)
                    while self._outgoing.get() is not _END:
                        pass
                    return
                counter += 1
                item = pb.ConnectRequest(keep_alive=pb.KeepAlive(counter=counter))
            if item is _END:
                return
            if item is not _TIMED:
                last = time.monotonic()
                yield item
