"""StateService: the device's live state, cycle by cycle (DESIGN.md section 8)."""
from __future__ import annotations

from landscape.server import services
from landscape.server.device import Device
from landscape.server.servicers.guard import guarded


@guarded(services.STATE)
class StateServicer(services.STATE.servicer_base):
    def __init__(self, device: Device):
        self.device = device
