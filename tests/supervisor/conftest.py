"""Fixtures of the dashboard tests: a real device server (lock-step clock at the pace of real
time, so motions last as long as on the arm), the real backend, and headless Chromium."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from dashboard_support import DashboardThread, browser  # noqa: E402
from support import start_server


@pytest.fixture
def cell_server():
    running = start_server(lockstep_pace=1.0)
    yield running
    running.stop(grace=None)


@pytest.fixture
def dashboard(cell_server):
    running = DashboardThread({"arm1": cell_server.target})
    yield running
    running.stop()


@pytest.fixture(scope="module")
def chromium():
    with browser() as running:
        yield running
