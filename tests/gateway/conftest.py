"""Fixtures: a real device server (lock-step clock) and the real gateway before it."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from crcl_support import RunningGateway  # noqa: E402


@pytest.fixture
def gateway(server):
    running = RunningGateway(server.target)
    yield running
    running.close()
