"""EventService: the device's event bus as a server stream (seed section 2.1).

Thin: subscribe to the bus, convert each domain event to its landscape.v1 message, stream it
until the client cancels or the server closes the bus. Any client may subscribe; no lease.
Waiting for the next event costs no thread: the bus wakes the stream on the event loop.
"""
from __future__ import annotations

import functools

from landscape.server.api import convert, services
from landscape.server import errors
from landscape.server.events import bus as events
from landscape.server.api.convert import event_to_proto
from landscape.server.api.guard import guarded
from landscape.server.api.servicers.alarms import AlarmAcknowledging
from landscape.server.events.acknowledgements import Acknowledgements
from landscape.v1 import event_service_pb2 as pb


@guarded(services.EVENTS)
class EventServicer(AlarmAcknowledging, services.EVENTS.servicer_base):
    def __init__(self, device, bus: events.EventBus, dispatch, limits,
                 shared_conversions: int = 1024):
        self.device, self.dispatch, self.limits = device, dispatch, limits
        self._bus = bus
        self.acknowledgements = Acknowledgements(bus)
        # Every subscriber sends the same events: convert each once (~13 us), not once per
        # subscriber. The cached messages are only ever serialized, never changed.
        self._response = functools.lru_cache(maxsize=shared_conversions)(_response)

    async def Subscribe(self, request, context):
        after = request.after_sequence if request.HasField("after_sequence") else None
        try:
            subscription = self._bus.subscribe(after)
        except events.SequenceOutOfRange as err:
            raise errors.OutOfRange(str(err)) from err
        with subscription:
            # The headers say "subscribed": a client may wait for them before it acts, even
            # where no event comes for a long while.
            await context.send_initial_metadata(())
            while (event := await subscription.next_async()) is not None:
                yield self._response(event)

    def PostMessage(self, request, context):
        event = self.device.post_message(request.text)
        return pb.PostMessageResponse(ret_val=convert.ok("posted"), sequence=event.sequence)


# -- Domain -> wire -------------------------------------------------------------------------

def _response(event: events.Event) -> pb.SubscribeResponse:
    return pb.SubscribeResponse(event=event_to_proto(event))
