"""Fixtures: a real device server (lock-step clock) and the real gateway before it, directly or
through a forwarding proxy that counts the device calls and can stall a stream."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from crcl_support import XSD, RawClient, RunningGateway, field  # noqa: E402
from landscape.gateway.workstation import Workstation  # noqa: E402
from grpc_proxy import GrpcProxy  # noqa: E402


@pytest.fixture
def gateway(request, server):
    """The gateway validating against the folder a module names in CRCL_SCHEMAS (NIST's 2021
    revision, for the commands it adds), else the installed schemas (crcl4java's 2018); its
    workstation is the module's CRCL_WORKSTATION, else the robot base with units as CRCL's."""
    running = RunningGateway(server.target, schemas=getattr(request.module, "CRCL_SCHEMAS", XSD),
                             workstation=getattr(request.module, "CRCL_WORKSTATION",
                                                 Workstation()))
    yield running
    running.close()


@pytest.fixture
def client(gateway):
    """A CRCL client in a session (its InitCanon done), checking every status against the
    gateway's schemas. Modules that need one before InitCanon define their own."""
    c = RawClient(gateway.port, schemas=gateway.schemas)
    assert field(c.run("InitCanon", 1), "CommandState") == "CRCL_Done"
    yield c
    c.close()


@pytest.fixture
def proxied(server):
    """The gateway reaching the device server through a proxy that can stall the state
    stream (at 5 samples a simulated second: the lock-step clock runs some 10 times faster than
    the wall clock, and the proxy forwards that many with time to spare)."""
    proxy = GrpcProxy(server.target)
    gateway = RunningGateway(proxy.target, state_rate_hz=5.0)
    client = RawClient(gateway.port)
    assert field(client.run("InitCanon", 1), "CommandState") == "CRCL_Done"
    yield proxy, gateway, client
    client.close()
    gateway.close()
    proxy.close()
