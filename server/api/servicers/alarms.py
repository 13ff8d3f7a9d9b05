"""EventService.AcknowledgeAlarm: an alarm acknowledged on the device, named by who did it
(the caller as the security layer found it: caller.py), seen by every subscriber.

A mixin of EventServicer (events.py): the guard finds this body through it.
"""
from __future__ import annotations

from landscape.server.api import convert
from landscape.server.api.caller import caller_of
from landscape.v1 import event_service_pb2 as pb


class AlarmAcknowledging:
    """`self.acknowledgements` is EventServicer's (events/acknowledgements.py)."""

    def AcknowledgeAlarm(self, request, context):
        caller = caller_of(context)
        event, newly = self.acknowledgements.acknowledge(request.sequence, caller.who,
                                                         caller.client, caller.on_behalf_of)
        acknowledgement = event.detail
        said = (f"alarm {request.sequence} acknowledged" if newly else
                f"alarm {request.sequence} was acknowledged already, by {acknowledgement.by}")
        return pb.AcknowledgeAlarmResponse(
            ret_val=convert.ok(said), acknowledgement=convert.detail_to_proto(acknowledgement),
            event_sequence=event.sequence, newly=newly)
