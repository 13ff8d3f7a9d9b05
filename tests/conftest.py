"""Shared fixtures: a real device server on a free loopback port, channels to it, and one
with TLS and role tokens."""
from __future__ import annotations

import grpc
import pytest

from support import make_keys, start_secured_server, start_server


@pytest.fixture
def server():
    running = start_server()
    yield running
    running.stop(grace=None)


@pytest.fixture
def channel(server):
    with grpc.insecure_channel(server.target) as ch:
        grpc.channel_ready_future(ch).result(timeout=5)
        yield ch


@pytest.fixture(scope="module")
def keys(tmp_path_factory):
    """A development CA, a server certificate and one token file per role."""
    return make_keys(tmp_path_factory.mktemp("keys"))


@pytest.fixture
def secured(keys):
    """A device server with TLS and the keys' role tokens."""
    running = start_secured_server(keys)
    yield running
    running.stop(grace=None)
