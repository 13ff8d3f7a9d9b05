"""The landscape.v1 services this device server exposes, in one table.

Each entry names the generated module pair and the service; the server, its health and
reflection registrations and the tests all read this table, so a service is added once.
"""
from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType

import grpc

from landscape.v1 import (audit_service_pb2, audit_service_pb2_grpc, device_service_pb2,
                          device_service_pb2_grpc, digital_io_service_pb2,
                          digital_io_service_pb2_grpc, event_service_pb2, event_service_pb2_grpc,
                          recording_service_pb2, recording_service_pb2_grpc, session_service_pb2, session_service_pb2_grpc, state_service_pb2,
                          state_service_pb2_grpc)


@dataclass(frozen=True)
class ServiceSpec:
    name: str            # short name, e.g. "DeviceService"
    pb2: ModuleType      # messages module (holds the file descriptor)
    grpc: ModuleType     # generated stubs and servicer base class

    @property
    def full_name(self) -> str:
        return self.pb2.DESCRIPTOR.services_by_name[self.name].full_name

    @property
    def descriptor(self):
        return self.pb2.DESCRIPTOR.services_by_name[self.name]

    @property
    def servicer_base(self) -> type:
        return getattr(self.grpc, f"{self.name}Servicer")

    def add_to_server(self, servicer, server) -> None:
        """The generated registration, except that the requests of RAW_REQUESTS reach the
        servicer as their bytes (grpc would parse them on the event loop), and the servicer
        sends the responses of RAW_RESPONSES as bytes it has serialized."""
        handlers = _Handlers()
        getattr(self.grpc, f"add_{self.name}Servicer_to_server")(servicer, handlers)
        table = handlers.table
        for method in RAW_REQUESTS.get(self.name, ()):
            handler = table[method]
            table[method] = grpc.stream_unary_rpc_method_handler(
                handler.stream_unary, response_serializer=handler.response_serializer)
        for method in RAW_RESPONSES.get(self.name, ()):
            handler = table[method]
            table[method] = grpc.unary_stream_rpc_method_handler(
                handler.unary_stream, request_deserializer=handler.request_deserializer)
        # Generic handlers only: grpc.aio keeps a pending request per registered method and
        # waits on all of them for every call (58 tasks: about 100 us of the event loop's time
        # per call, issue 31 item 1); a generic handler is one dictionary lookup.
        server.add_generic_rpc_handlers((grpc.method_handlers_generic_handler(
            self.full_name, table),))


class GenericOnly:
    """Stands in for `server` while generated code (health, reflection) registers a service:
    its handlers become generic ones (ServiceSpec.add_to_server says why)."""

    def __init__(self, server):
        self._server = server

    def add_generic_rpc_handlers(self, handlers) -> None:
        self._server.add_generic_rpc_handlers(handlers)

    def add_registered_method_handlers(self, service: str, table: dict) -> None:
        self._server.add_generic_rpc_handlers((grpc.method_handlers_generic_handler(
            service, table),))


class _Handlers:
    """Stands in for the server while the generated code registers a service's handlers."""

    def add_generic_rpc_handlers(self, handlers) -> None:
        pass

    def add_registered_method_handlers(self, service: str, table: dict) -> None:
        self.table = table


# Client-streaming calls whose messages the servicer takes as bytes: a PathLoad message of
# 10,000 points takes about 0.5 ms to parse, which is the planning process's job, not the
# event loop's (planning_process.py).
RAW_REQUESTS = {"DeviceService": ("PathLoad",)}

# Server-streaming calls whose servicer yields serialized messages: every subscriber of the
# event stream sends the same event, serialized once for all of them (servicers/events.py).
RAW_RESPONSES = {"EventService": ("Subscribe",)}


DEVICE = ServiceSpec("DeviceService", device_service_pb2, device_service_pb2_grpc)
DIGITAL_IO = ServiceSpec("DigitalIOService", digital_io_service_pb2, digital_io_service_pb2_grpc)
EVENTS = ServiceSpec("EventService", event_service_pb2, event_service_pb2_grpc)
SESSIONS = ServiceSpec("SessionService", session_service_pb2, session_service_pb2_grpc)
STATE = ServiceSpec("StateService", state_service_pb2, state_service_pb2_grpc)
RECORDINGS = ServiceSpec("RecordingService", recording_service_pb2, recording_service_pb2_grpc)
AUDIT = ServiceSpec("AuditService", audit_service_pb2, audit_service_pb2_grpc)

ALL = (DEVICE, DIGITAL_IO, EVENTS, SESSIONS, STATE, RECORDINGS, AUDIT)
