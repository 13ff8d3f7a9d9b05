"""Fixtures of the dashboard tests: a real device server (lock-step clock at the pace of real
time, so motions last as long as on the arm), the real backend, and headless Chromium."""
from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).parent))
from dashboard_support import DashboardThread, People, browser  # noqa: E402
from support import start_server


# The backend serves the built page: without Node.js and npm it is not built (the Makefile says
# so), and the tests that start the backend skip, naming what is missing.
PAGE = Path(__file__).resolve().parents[2] / "supervisor_gui_web" / "frontend" / "dist"
NEED_THE_PAGE = {"test_backend.py", "test_page.py", "test_page_panels.py", "test_http_guard.py",
                 "test_page_trust.py", "test_jog_press.py", "test_page_lost.py",
                 "test_page_status.py", "test_page_words.py", "test_page_layout.py",
                 "test_page_operations.py", "test_page_a11y.py", "test_page_cell.py",
                 "test_handover.py", "test_page_alarms.py",
                 "test_supervisor_calls.py", "test_metrics.py"}
ROOT = Path(__file__).resolve().parents[2]


def pytest_collection_modifyitems(items):
    if (PAGE / "index.html").is_file():
        return
    skip = pytest.mark.skip(reason=f"the web supervisor's page is not built ({PAGE} is missing: "
                                   "it needs Node.js and npm, then `make install`)")
    for item in items:
        if item.path.parent == Path(__file__).parent and item.path.name in NEED_THE_PAGE:
            item.add_marker(skip)


@pytest.fixture
def cell_server():
    running = start_server(lockstep_pace=1.0)
    yield running
    running.stop(grace=None)


@pytest.fixture
def two_arm_servers():
    """A cell of two arms: two device servers on the lock-step clock at the pace of real time,
    the second in the press-tending world (a TX90L)."""
    first = start_server(lockstep_pace=1.0)
    second = start_server(lockstep_pace=1.0, cell=str(ROOT / "robot" / "cells" / "press_tending.toml"))
    yield first, second
    first.stop(grace=None)
    second.stop(grace=None)


@pytest.fixture
def two_arm_dashboard(two_arm_servers, people):
    first, second = two_arm_servers
    running = DashboardThread({"arm1": first.target, "arm2": second.target}, people)
    yield running
    running.stop()


@pytest.fixture(scope="session")
def people(tmp_path_factory) -> People:
    """The people who sign in (dashboard_support.PEOPLE), with their tokens."""
    return People.make(tmp_path_factory.mktemp("people"))


@pytest.fixture
def dashboard(cell_server, people):
    running = DashboardThread({"arm1": cell_server.target}, people)
    yield running
    running.stop()


@pytest.fixture(scope="module")
def chromium():
    with browser() as running:
        yield running
