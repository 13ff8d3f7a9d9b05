"""EventService: the device's event bus as a server stream (seed section 2.1).

Thin: subscribe to the bus, convert each domain event to its landscape.v1 message, stream it
until the client cancels or the server closes the bus. Any client may subscribe; no lease.
"""
from __future__ import annotations

import functools

import grpc
from google.protobuf import timestamp_pb2

from landscape.server import errors, events, services
from landscape.v1 import event_service_pb2 as pb

_PHASES = {phase: pb.CommandEvent.Phase.Value(f"PHASE_{phase.name}") for phase in events.Phase}
_SEVERITIES = {severity: pb.AlarmSeverity.Value(f"ALARM_SEVERITY_{severity.name}")
               for severity in events.Severity}


class EventServicer(services.EVENTS.servicer_base):
    def __init__(self, bus: events.EventBus, shared_conversions: int = 1024):
        self._bus = bus
        # Every subscriber sends the same events: convert each once (~13 us), not once per
        # subscriber. The cached messages are only ever serialized, never changed.
        self._response = functools.lru_cache(maxsize=shared_conversions)(_response)

    def Subscribe(self, request, context: grpc.ServicerContext):
        after = request.after_sequence if request.HasField("after_sequence") else None
        try:
            subscription = self._bus.subscribe(after)
        except events.SequenceOutOfRange as err:
            raise errors.OutOfRange(str(err)) from err
        # A cancelled or broken stream closes the subscription, which wakes the loop below.
        if not context.add_callback(subscription.close):
            subscription.close()
        with subscription:
            for event in subscription:
                yield self._response(event)


# -- Domain -> wire -------------------------------------------------------------------------

def _response(event: events.Event) -> pb.SubscribeResponse:
    return pb.SubscribeResponse(event=event_to_proto(event))


def event_to_proto(event: events.Event) -> pb.Event:
    """The landscape.v1 Event for a domain event (time: unix seconds -> Timestamp)."""
    field, detail = _DETAILS[type(event.detail)](event.detail)
    return pb.Event(sequence=event.sequence, time=_timestamp(event.time),
                    event_id=event.event_id, data=event.data, **{field: detail})


def detail_to_proto(detail: events.Detail):
    """The landscape.v1 message for one detail record, e.g. an RsvpRequest for a session."""
    return _DETAILS[type(detail)](detail)[1]


def _timestamp(unix_s: float) -> timestamp_pb2.Timestamp:
    stamp = timestamp_pb2.Timestamp()
    stamp.FromNanoseconds(round(unix_s * 1e9))
    return stamp


def _command(d: events.CommandEvent):
    return "command", pb.CommandEvent(
        command_id=d.command_id, command=d.command, phase=_PHASES[d.phase],
        point_name=d.point_name, tag_name=d.tag_name, tag_index=d.tag_index, message=d.message)


def _alarm(d: events.Alarm):
    return "alarm", pb.Alarm(severity=_SEVERITIES[d.severity], code=d.code, message=d.message,
                             command_id=d.command_id)


def _state_change(d: events.StateChange):
    return "state_change", pb.StateChange(from_state=d.from_state, to_state=d.to_state,
                                          reason=d.reason)


def _digital_io(d: events.DigitalIOSignal):
    return "digital_io", pb.DigitalIOSignal(command_id=d.command_id, type=d.type,
                                            unit_id=d.unit_id, bit_string=d.bit_string,
                                            bits_on=d.bits_on)


def _rsvp_request(d: events.RsvpRequest):
    return "rsvp_request", pb.RsvpRequest(
        rsvp_id=d.rsvp_id, alarm=d.alarm, event_id=d.event_id, data=d.data, choices=d.choices,
        default_choice=d.default_choice, timeout_ms=round(d.timeout_s * 1000))


def _rsvp_answer(d: events.RsvpAnswer):
    return "rsvp_answer", pb.RsvpAnswer(rsvp_id=d.rsvp_id, choice=d.choice, data=d.data,
                                        timed_out=d.timed_out)


def _events_lost(d: events.EventsLost):
    return "events_lost", pb.EventsLost(first_sequence=d.first_sequence,
                                        last_sequence=d.last_sequence)


# One converter per detail type: (the Event oneof field, its message).
_DETAILS = {
    events.CommandEvent: _command, events.Alarm: _alarm, events.StateChange: _state_change,
    events.DigitalIOSignal: _digital_io, events.RsvpRequest: _rsvp_request,
    events.RsvpAnswer: _rsvp_answer, events.EventsLost: _events_lost,
}
