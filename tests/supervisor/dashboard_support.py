"""The real dashboard backend in a thread of the test process, and a real Chromium from Debian."""
from __future__ import annotations

import asyncio
import contextlib
import os
import threading
from concurrent.futures import Future

import pytest

from landscape.supervisor import DashboardConfig, DeviceTarget, start

CHROMIUM = "/usr/bin/chromium"
# As root, in a sandbox without a network: no sandbox, no background connections, no GPU.
CHROMIUM_ARGS = ["--no-sandbox", "--disable-background-networking", "--disable-gpu",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]


class DashboardThread:
    """`python -m landscape.supervisor` as a test runs it: the same app on its own event loop,
    in a thread, on a free loopback port."""

    def __init__(self, devices: dict[str, str], **config):
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="dashboard", daemon=True)
        self._thread.start()
        targets = tuple(DeviceTarget(name, target) for name, target in devices.items())
        self._running = self.run(start(DashboardConfig(devices=targets, port=0, **config)))
        self.url = self._running.url

    def run(self, coroutine, timeout: float = 30.0):
        """Run a coroutine on the dashboard's loop and wait for its result."""
        future: Future = asyncio.run_coroutine_threadsafe(coroutine, self._loop)
        return future.result(timeout)

    def stop(self) -> None:
        self.run(self._running.stop())
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=10)


def chromium_or_skip():
    if not os.access(CHROMIUM, os.X_OK):
        pytest.skip(f"{CHROMIUM} is absent: the page tests need Debian's chromium "
                    "(apt-get install -y chromium); no browser is downloaded")
    playwright = pytest.importorskip("playwright.sync_api")
    return playwright


@contextlib.contextmanager
def browser():
    """Headless Debian Chromium driven by Playwright (never a downloaded browser)."""
    sync_api = chromium_or_skip()
    with sync_api.sync_playwright() as p:
        chromium = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS, headless=True)
        try:
            yield chromium
        finally:
            chromium.close()
