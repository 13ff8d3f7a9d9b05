"""SessionService.Connect: a client's session, its keep-alives and RSVP answers (seed 2.2)."""
from __future__ import annotations

import asyncio
import logging

import grpc

from landscape.server.api import request_bounds, convert, services
from landscape.server.device.device import Device
from landscape.server.errors import CommandError, ParamError
from landscape.server.api.guard import Dispatch, guarded
from landscape.server.device.sessions import Outbox
from landscape.v1 import session_service_pb2 as pb

log = logging.getLogger(__name__)

END_CODES = {"DEADLINE_EXCEEDED": grpc.StatusCode.DEADLINE_EXCEEDED,
             "UNAVAILABLE": grpc.StatusCode.UNAVAILABLE}


@guarded(services.SESSIONS)
class SessionServicer(services.SESSIONS.servicer_base):
    def __init__(self, device: Device, dispatch: Dispatch, limits):
        self.device, self.dispatch, self.limits = device, dispatch, limits

    async def Connect(self, request_iterator, context):
        registry = self.device.sessions
        first = await anext(aiter(request_iterator), None)
        if first is None or first.WhichOneof("message") != "hello":
            raise ParamError("a session starts with a hello message")
        request_bounds.check(first)
        session = registry.open(first.hello.client_name, asyncio.get_running_loop())
        reader = asyncio.create_task(self._read(request_iterator, session))
        try:
            yield pb.ConnectResponse(opened=pb.SessionOpened(
                session_id=session.id,
                keepalive_interval_ms=round(registry.keepalive_interval * 1000),
                keepalive_timeout_ms=round(registry.keepalive_timeout * 1000),
                session_secret=session.secret))
            while (item := await session.outbox.get()) is not Outbox.END:
                yield pb.ConnectResponse(rsvp_request=convert.detail_to_proto(item))
            if session.end_code in END_CODES:   # the server ended it: say why
                await context.abort(END_CODES[session.end_code], session.end_reason)
        finally:
            reader.cancel()
            # Whatever ended the call (client gone, cancelled, server stopping) ends the
            # session; the disconnect handler runs on the device's safety worker, not here.
            registry.end(session, "stream closed")

    async def _read(self, request_iterator, session) -> None:
        registry = self.device.sessions
        reason = "stream closed by the client"
        try:
            async for message in request_iterator:
                registry.touch(session)   # any message counts as a keep-alive
                if message.WhichOneof("message") == "rsvp_answer":
                    try:
                        request_bounds.check(message)
                    except CommandError as error:
                        log.warning("session %s: answer refused: %s", session.id, error)
                        continue
                    answer = message.rsvp_answer
                    if not self.device.rsvp.answer(session, answer.rsvp_id, answer.choice,
                                                   list(answer.data)):
                        log.warning("session %s answered %r with %r: no such question waits",
                                    session.id, answer.rsvp_id, answer.choice)
        except asyncio.CancelledError:
            return
        except Exception as exc:  # the transport failed: the session is over all the same
            reason = f"stream failed: {type(exc).__name__}"
        registry.end(session, reason)
