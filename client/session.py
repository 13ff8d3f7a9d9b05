"""A session for programs that drive the generated stubs on a synchronous channel themselves
(probes, tests): the Connect stream, keep-alives, the lock's lease and answers to the device's
RSVP questions, on threads.

    with grpc.insecure_channel(target) as channel, Session(channel, "cell-supervisor") as session:
        device = DeviceServiceStub(session.channel)   # calls carry the lease once locked
        session.lock()
        device.Activate(ActivateRequest())

Front ends and client programs use the client core instead (AsyncRobot, Robot, DeviceLink),
whose sessions keep their keep-alives on keeper threads and report a lost session.
"""
from __future__ import annotations

import queue
import threading
from typing import Callable

import grpc

from landscape.client.aio_session import LEASE_KEY
from landscape.client.credentials import CallDetails
from landscape.v1 import control_pb2, device_service_pb2_grpc, event_service_pb2
from landscape.v1 import session_service_pb2 as pb
from landscape.v1 import session_service_pb2_grpc

# Decides an RSVP: returns the choice and the (inout) data.
RsvpHandler = Callable[[event_service_pb2.RsvpRequest], tuple[str, list[str]]]


class Session:
    """One session: opened on enter, keep-alives every interval the server asks for, closed on
    exit (the device then runs its disconnect handler if this session held the lock)."""

    def __init__(self, channel: grpc.Channel, client_name: str, on_rsvp: RsvpHandler | None = None,
                 open_timeout: float = 10.0):
        self._raw_channel = channel
        self.client_name = client_name
        self.on_rsvp = on_rsvp
        self.lease: str | None = None
        self.channel = grpc.intercept_channel(channel, _LeaseInterceptor(self))
        self.rsvp_requests: queue.Queue = queue.Queue()   # every question asked, for inspection
        self._outgoing: queue.Queue = queue.Queue()
        self._closed = threading.Event()
        self._open_timeout = open_timeout
        self.session_id = ""
        self.session_secret = ""
        self.end_status: grpc.StatusCode | None = None   # why the server ended it, if it did
        self.end_details = ""

    def __enter__(self) -> "Session":
        return self.open()

    def __exit__(self, *exc) -> None:
        self.close()

    def open(self) -> "Session":
        stub = session_service_pb2_grpc.SessionServiceStub(self._raw_channel)
        self._outgoing.put(pb.ConnectRequest(hello=pb.Hello(client_name=self.client_name)))
        self._call = stub.Connect(self._requests())
        opened = next(self._call).opened   # raises the RPC's error if the server refuses
        self.session_id = opened.session_id
        self.session_secret = opened.session_secret
        self._interval = opened.keepalive_interval_ms / 1000.0
        for target in (self._keep_alive, self._read):
            threading.Thread(target=target, daemon=True, name=f"session-{target.__name__}").start()
        return self

    def close(self) -> None:
        if not self._closed.is_set():
            self._closed.set()
            self._outgoing.put(None)
            self._call.cancel()

    def lock(self, timeout: float = 10.0) -> str:
        stub = device_service_pb2_grpc.DeviceServiceStub(self._raw_channel)
        reply = stub.Lock(control_pb2.LockRequest(session_id=self.session_id,
                                                   session_secret=self.session_secret), timeout=timeout)
        self.lease = reply.lease
        return self.lease

    # -- the stream
    def _requests(self):
        while (item := self._outgoing.get()) is not None:
            yield item

    def _keep_alive(self) -> None:
        counter = 0
        while not self._closed.wait(self._interval):
            counter += 1
            self._outgoing.put(pb.ConnectRequest(keep_alive=pb.KeepAlive(counter=counter)))

    def _read(self) -> None:
        try:
            for message in self._call:
                if message.WhichOneof("message") == "rsvp_request":
                    self._answer(message.rsvp_request)
        except grpc.RpcError as error:   # cancelled by close(), or the server ended it
            self.end_status, self.end_details = error.code(), error.details() or ""
        finally:
            self._closed.set()

    def _answer(self, request) -> None:
        self.rsvp_requests.put(request)
        if self.on_rsvp is None:
            return  # unanswered: the device takes its default when the time is up
        choice, data = self.on_rsvp(request)
        self._outgoing.put(pb.ConnectRequest(rsvp_answer=event_service_pb2.RsvpAnswer(
            rsvp_id=request.rsvp_id, choice=choice, data=data)))


class _LeaseInterceptor(grpc.UnaryUnaryClientInterceptor, grpc.UnaryStreamClientInterceptor,
                        grpc.StreamUnaryClientInterceptor, grpc.StreamStreamClientInterceptor):
    """Adds the session's lease to every call once it holds the lock."""

    def __init__(self, session: Session):
        self._session = session

    def _details(self, details):
        if not self._session.lease:
            return details
        metadata = [*(details.metadata or ()), (LEASE_KEY, self._session.lease)]
        return CallDetails(details.method, details.timeout, metadata, details.credentials,
                            details.wait_for_ready, details.compression)

    def intercept_unary_unary(self, continuation, details, request):
        return continuation(self._details(details), request)

    def intercept_unary_stream(self, continuation, details, request):
        return continuation(self._details(details), request)

    def intercept_stream_unary(self, continuation, details, request_iterator):
        return continuation(self._details(details), request_iterator)

    def intercept_stream_stream(self, continuation, details, request_iterator):
        return continuation(self._details(details), request_iterator)
