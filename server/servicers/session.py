"""SessionService.Connect: a client's session, its keep-alives and RSVP answers (seed 2.2)."""
from __future__ import annotations

import logging
import queue
import threading

from landscape.server import convert, services
from landscape.server.device import Device
from landscape.server.errors import ParamError
from landscape.server.events import RsvpRequest
from landscape.server.servicers.guard import guarded
from landscape.v1 import session_service_pb2 as pb

log = logging.getLogger(__name__)


@guarded(services.SESSIONS)
class SessionServicer(services.SESSIONS.servicer_base):
    def __init__(self, device: Device):
        self.device = device

    def Connect(self, request_iterator, context):
        registry = self.device.sessions
        first = next(request_iterator, None)
        if first is None or first.WhichOneof("message") != "hello":
            raise ParamError("a session starts with a hello message")
        session = registry.open(first.hello.client_name)
        # Whatever ends the call (client gone, cancelled, server stopping) ends the session.
        context.add_callback(lambda: registry.end(session, "stream closed"))
        threading.Thread(target=self._read, args=(request_iterator, session),
                         name=f"session-{session.id}", daemon=True).start()
        yield pb.ConnectResponse(opened=pb.SessionOpened(
            session_id=session.id,
            keepalive_interval_ms=round(registry.keepalive_interval * 1000),
            keepalive_timeout_ms=round(registry.keepalive_timeout * 1000),
            session_secret=session.secret))
        while not session.ended.is_set():
            try:
                item = session.outbox.get(timeout=0.1)
            except queue.Empty:
                continue
            if isinstance(item, RsvpRequest):
                item = pb.ConnectResponse(rsvp_request=convert.detail_to_proto(item))
            yield item

    def _read(self, request_iterator, session) -> None:
        registry = self.device.sessions
        reason = "stream closed by the client"
        try:
            for message in request_iterator:
                registry.touch(session)   # any message counts as a keep-alive
                if message.WhichOneof("message") == "rsvp_answer":
                    answer = message.rsvp_answer
                    if not self.device.rsvp.answer(session, answer.rsvp_id, answer.choice,
                                                   list(answer.data)):
                        log.warning("session %s answered %r with %r: no such question waits",
                                    session.id, answer.rsvp_id, answer.choice)
        except Exception as exc:  # the transport failed: the session is over all the same
            reason = f"stream failed: {type(exc).__name__}"
        registry.end(session, reason)

