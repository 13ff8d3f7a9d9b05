"""The landscape.v1 RPCs a browser may call, found by name in the contract's descriptors.

The table is read from the generated descriptors, not written by hand: an RPC added to the
contract is callable from the page as soon as the stubs are rebuilt (the client core's
AsyncRobot.invoke makes the call, by service and method name).
"""
from __future__ import annotations

from dataclasses import dataclass

from google.protobuf import message_factory
from google.protobuf.descriptor import MethodDescriptor

from landscape.v1 import (audit_service_pb2, device_service_pb2, digital_io_service_pb2,
                          event_service_pb2, recording_service_pb2, session_service_pb2,
                          state_service_pb2)

# Services whose RPCs the browser calls through the backend. StateService and EventService are
# fed to every browser by the backend itself (one stream per device, shared), so they are here
# for their names only.
SERVICES = {
    "DeviceService": device_service_pb2,
    "DigitalIOService": digital_io_service_pb2,
    "SessionService": session_service_pb2,
    "StateService": state_service_pb2,
    "EventService": event_service_pb2,
    "RecordingService": recording_service_pb2,
    "AuditService": audit_service_pb2,
}


@dataclass(frozen=True)
class Rpc:
    name: str                # "landscape.v1.DeviceService/Activate", as on the wire
    method: MethodDescriptor
    request_class: type
    response_class: type

    @property
    def service(self) -> str:   # "DeviceService"
        return self.method.containing_service.name

    @property
    def kind(self) -> str:
        """"unary", "client_stream", "server_stream" or "bidi"."""
        client, server = self.method.client_streaming, self.method.server_streaming
        return {(False, False): "unary", (True, False): "client_stream",
                (False, True): "server_stream", (True, True): "bidi"}[(client, server)]


def _table() -> dict[str, Rpc]:
    table = {}
    for service_name, module in SERVICES.items():
        service = module.DESCRIPTOR.services_by_name[service_name]
        for method in service.methods:
            name = f"{service.full_name}/{method.name}"
            table[name] = Rpc(name, method, message_factory.GetMessageClass(method.input_type),
                              message_factory.GetMessageClass(method.output_type))
    return table


RPCS: dict[str, Rpc] = _table()


def rpc_name(service: str, method: str) -> str:
    """"landscape.v1.<service>/<method>", checked against the contract."""
    name = f"landscape.v1.{service}/{method}"
    if name not in RPCS:
        raise KeyError(f"{name} is not in the landscape.v1 contract")
    return name


CONNECT = rpc_name("SessionService", "Connect")
LOCK = rpc_name("DeviceService", "Lock")
RELEASE = rpc_name("DeviceService", "Release")
JOG = rpc_name("DeviceService", "Jog")
STREAM_STATE = rpc_name("StateService", "StreamState")
SUBSCRIBE = rpc_name("EventService", "Subscribe")
