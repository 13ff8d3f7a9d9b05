"""Shared fixtures: a real device server on a free loopback port, and channels to it."""
from __future__ import annotations

import grpc
import pytest

from landscape.server.app import serve
from landscape.server.config import ServerConfig


@pytest.fixture
def server():
    running = serve(ServerConfig(port=0))
    yield running
    running.stop(grace=None)


@pytest.fixture
def channel(server):
    with grpc.insecure_channel(server.target) as ch:
        grpc.channel_ready_future(ch).result(timeout=5)
        yield ch
