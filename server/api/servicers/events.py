"""EventService: the device's event bus as a server stream (seed section 2.1).

Thin: subscribe to the bus, convert each domain event to its landscape.v1 message, stream it
until the client cancels or the server closes the bus. Any client may subscribe; no lease.
Waiting for the next event costs no thread: the bus wakes the stream on the event loop.
"""
from __future__ import annotations

from collections import OrderedDict

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
        self._encoded = SharedEncoding(shared_conversions)

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
                yield self._encoded(event)   # bytes: services.RAW_RESPONSES

    def PostMessage(self, request, context):
        event = self.device.post_message(request.text)
        return pb.PostMessageResponse(ret_val=convert.ok("posted"), sequence=event.sequence)


# -- Domain -> wire -------------------------------------------------------------------------

class SharedEncoding:
    """Each event's SubscribeResponse, serialized once for every subscriber (converting and
    serializing one takes ~15 us: 50 subscribers paid it 50 times, issue 31 item 6): the
    newest `size` events' bytes, by sequence. A loss notice is one subscriber's own (it
    carries the sequence of the last event that subscriber lost, which the others received):
    encoded for it alone."""

    def __init__(self, size: int):
        self._size = size
        self._bytes: OrderedDict[int, bytes] = OrderedDict()

    def __call__(self, event: events.Event) -> bytes:
        if isinstance(event.detail, events.EventsLost):
            return _encode(event)
        encoded = self._bytes.get(event.sequence)
        if encoded is None:
            encoded = self._bytes[event.sequence] = _encode(event)
            if len(self._bytes) > self._size:
                self._bytes.popitem(last=False)
        return encoded


def _encode(event: events.Event) -> bytes:
    return pb.SubscribeResponse(event=event_to_proto(event)).SerializeToString()
