"""Shared fixtures: a real device server on a free loopback port, and channels to it."""
from __future__ import annotations

import grpc
import pytest

from support import start_server


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
