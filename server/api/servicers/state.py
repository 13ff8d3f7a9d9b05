"""StateService: the device's live state, cycle by cycle (DESIGN.md section 8)."""
from __future__ import annotations

from landscape.server.api import convert, services
from landscape.server.api.guard import guarded
from landscape.server.api.state_stream import StateHub
from landscape.v1 import state_service_pb2 as pb
from landscape.v1 import types_pb2


@guarded(services.STATE)
class StateServicer(services.STATE.servicer_base):
    def __init__(self, device, hub: StateHub, dispatch, limits):
        self.device, self.hub, self.dispatch, self.limits = device, hub, dispatch, limits

    async def StreamState(self, request, context):
        units = (convert.units_from_pb(request.units.linear, request.units.angular)
                 if request.HasField("units") else self.device.settings.units)
        frame = (None if request.frame == types_pb2.REFERENCE_FRAME_UNSPECIFIED else
                 convert.enum_value(convert.FRAMES, request.frame, "frame"))
        view, note = self.hub.view(request.rate_hz, frame, units, tuple(request.sensors))
        yield pb.StreamStateResponse(started=pb.StreamStarted(
            granted_rate_hz=1.0 / (view.period * self.device.link.cycle_time),
            cycle_time=self.device.link.cycle_time, note=note,
            frame=convert.FRAMES_PB[view.frame], units=convert.units_to_pb(view.units)))
        async for message in self.hub.stream(view):
            yield message
