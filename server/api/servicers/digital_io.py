"""DigitalIOService: the DIGITAL_IO IDL (seed section 4), behind the state table. Thin: convert,
call the cell's I/O (digital_io.py), wrap."""
from __future__ import annotations

from landscape.server.api import convert, services
from landscape.server.device.device import Device
from landscape.server.api.guard import blocking, guarded
from landscape.server.workcell.assembly import Workcell
from landscape.v1 import digital_io_service_pb2 as pb


@guarded(services.DIGITAL_IO)
class DigitalIOServicer(services.DIGITAL_IO.servicer_base):
    def __init__(self, device: Device, workcell: Workcell, dispatch, limits):
        self.device, self.io, self.dispatch, self.limits = device, workcell.io, dispatch, limits

    def SetDigitalIO(self, request, context):
        self.io.set(request.type, request.unit_id, request.bits_on, request.bits_off,
                    request.description)
        return pb.SetDigitalIOResponse(ret_val=convert.ok(
            f"{request.type} unit {request.unit_id}: bits {request.bits_on:#x} on, "
            f"{request.bits_off:#x} off"))

    @blocking
    def GetDigitalIO(self, request, context):
        bits = self.io.get(request.type, request.unit_id)
        return pb.GetDigitalIOResponse(ret_val=convert.ok(), bits_on=bits)

    @blocking
    def SignalDigitalIO(self, request, context):
        callback = convert.enum_value(convert.CALLBACKS, request.callback_type, "callback_type")
        command_id = self.io.signal(request.type, request.unit_id, request.bit_string,
                                    request.polling_timeout, request.polling_cycle_time, callback)
        return pb.SignalDigitalIOResponse(ret_val=convert.started(command_id))

    def ListDigitalIO(self, request, context):
        return pb.ListDigitalIOResponse(ret_val=convert.ok(), units=[
            pb.DigitalIOUnit(unit_id=unit.id, type=unit.direction, name=unit.name,
                             bits=[pb.DigitalIOBit(bit=bit, name=name) for bit, name in unit.bits])
            for unit in self.io.units.values()])
