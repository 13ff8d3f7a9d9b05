"""The services whose commands are not built yet: every RPC answers UNIMPLEMENTED by name."""
from __future__ import annotations

from landscape.server import services
from landscape.server.servicers.unimplemented import complete


class DigitalIOServicer(services.DIGITAL_IO.servicer_base):
    pass


class EventServicer(services.EVENTS.servicer_base):
    pass


class SessionServicer(services.SESSIONS.servicer_base):
    pass


for _cls, _spec in ((DigitalIOServicer, services.DIGITAL_IO), (EventServicer, services.EVENTS),
                    (SessionServicer, services.SESSIONS)):
    complete(_cls, _spec)
