"""The landscape.v1 services this device server exposes, in one table.

Each entry names the generated module pair and the service; the server, its health and
reflection registrations and the tests all read this table, so a service is added once.
"""
from __future__ import annotations

from dataclasses import dataclass
from types import ModuleType

from landscape.v1 import (device_service_pb2, device_service_pb2_grpc, digital_io_service_pb2,
                          digital_io_service_pb2_grpc, event_service_pb2, event_service_pb2_grpc,
                          session_service_pb2, session_service_pb2_grpc, state_service_pb2,
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
        getattr(self.grpc, f"add_{self.name}Servicer_to_server")(servicer, server)


DEVICE = ServiceSpec("DeviceService", device_service_pb2, device_service_pb2_grpc)
DIGITAL_IO = ServiceSpec("DigitalIOService", digital_io_service_pb2, digital_io_service_pb2_grpc)
EVENTS = ServiceSpec("EventService", event_service_pb2, event_service_pb2_grpc)
SESSIONS = ServiceSpec("SessionService", session_service_pb2, session_service_pb2_grpc)
STATE = ServiceSpec("StateService", state_service_pb2, state_service_pb2_grpc)

ALL = (DEVICE, DIGITAL_IO, EVENTS, SESSIONS, STATE)
