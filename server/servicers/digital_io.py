"""DigitalIOService: the DIGITAL_IO IDL (seed section 4), behind the state table."""
from __future__ import annotations

from landscape.server import services
from landscape.server.device import Device
from landscape.server.servicers.guard import guarded


@guarded(services.DIGITAL_IO)
class DigitalIOServicer(services.DIGITAL_IO.servicer_base):
    def __init__(self, device: Device, dispatch, limits):
        self.device, self.dispatch, self.limits = device, dispatch, limits
