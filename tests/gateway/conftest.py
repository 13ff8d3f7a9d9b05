"""Fixtures: a real device server (lock-step clock) and the real gateway before it."""
from __future__ import annotations

import pytest

from crcl_support import RunningGateway


@pytest.fixture
def gateway(server):
    running = RunningGateway(server.target)
    yield running
    running.close()
