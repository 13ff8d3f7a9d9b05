"""A lost session or lock reaches the person at once (issue 25 item 4, the page's part), in
Debian's headless Chromium: the supervisor runs in a process of its own, which the test
starves (SIGSTOP past the device's keep-alive) or kills; the page says what happened and why,
with the controls disabled and one button to take the lock back, and nothing takes it back
by itself. Screenshots go to var/screenshots (not in git)."""
from __future__ import annotations

import os
import signal

import pytest

from dashboard_support import Page, SpawnedDashboard
from landscape.server.device.states import State
from support import wait_until


@pytest.fixture
def spawned(cell_server, people):
    running = SpawnedDashboard({"arm1": cell_server.target}, people)
    yield running
    running.stop()


def test_a_session_starved_past_its_keep_alive_is_said_with_the_devices_reason(
        chromium, spawned, cell_server):
    page = Page(chromium, spawned, name="olga")
    page.take_control()
    os.kill(spawned.pid, signal.SIGSTOP)   # the backend's keep-alives stop
    try:
        wait_until(lambda: cell_server.device.state is State.UNLOCKED, timeout=30)
    finally:
        os.kill(spawned.pid, signal.SIGCONT)
    lost = page.page.get_by_test_id("lost-arm1")
    page.expect(lost).to_contain_text("Your session ended", timeout=30_000)
    # The device's reason: in its session status, and in its alarm (the status alone may be
    # garbled by grpc.aio after a stall, grpc/grpc#36066: the page shows both).
    page.expect(lost).to_contain_text(
        "The device: lock holder olga disconnected (no keep-alive for 2 s)", timeout=30_000)
    # A status grpc.aio garbled after the stall is said in words, never as gRPC's own.
    assert "Internal error from Core" not in page.page.inner_text("body")
    for button in ("btn-activate", "btn-release", "btn-path-run", "btn-lock"):
        assert page.page.locator(f"#{button}").is_disabled(), button
    page.screenshot("session-lost")
    page.page.wait_for_timeout(1000)
    assert not cell_server.device.status().locked   # nothing took it back by itself
    page.page.get_by_test_id("take-back-arm1").click()   # one click does
    page.shows("st-lock", "olga")
    page.expect(lost).to_be_hidden()
    assert cell_server.device.status().lock_holder == "olga"
    assert cell_server.device.state is State.INACTIVE
    page.close()


def test_the_pages_connection_closing_is_said_and_the_lock_is_not_taken_back(
        chromium, spawned, cell_server):
    page = Page(chromium, spawned, name="olga")
    page.take_control()
    os.kill(spawned.pid, signal.SIGKILL)
    page.expect(page.page.get_by_test_id("lost-arm1")).to_contain_text(
        "The connection to the supervisor was lost (WebSocket closed, code 1006)", timeout=30_000)
    page.shows("connection", "disconnected")
    assert page.page.locator("#btn-activate").is_disabled()
    wait_until(lambda: cell_server.device.state is State.UNLOCKED, timeout=30)
    page.screenshot("connection-lost")
    page.close()
