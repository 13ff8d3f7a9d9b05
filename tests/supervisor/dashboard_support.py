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


class Page:
    """One browser tab on the dashboard, as an operator uses it: buttons by their ids, what the
    page shows by its ids. Every wait has a timeout; errors in the page fail the test."""

    TIMEOUT_MS = 30_000

    def __init__(self, chromium, url: str, name: str | None = None):
        self.context = chromium.new_context(viewport={"width": 1400, "height": 1000})
        self.page = self.context.new_page()
        self.errors: list[str] = []
        self.page.on("pageerror", lambda error: self.errors.append(str(error)))
        self.page.goto(url)
        if name:
            self.page.fill("#client-name", name)
        from playwright.sync_api import expect
        self.expect = expect
        expect(self.page.locator("#connection")).to_have_text("connected", timeout=self.TIMEOUT_MS)
        expect(self.page.locator("#joints .joint")).to_have_count(6, timeout=self.TIMEOUT_MS)

    def click(self, element_id: str) -> None:
        self.page.click(f"#{element_id}", timeout=self.TIMEOUT_MS)

    def text(self, element_id: str) -> str:
        return self.page.inner_text(f"#{element_id}", timeout=self.TIMEOUT_MS)

    def shows(self, element_id: str, text: str, timeout_ms: int | None = None) -> None:
        """Waits until the element's text contains `text`."""
        self.expect(self.page.locator(f"#{element_id}")).to_contain_text(
            text, timeout=timeout_ms or self.TIMEOUT_MS)

    def log_has(self, text: str, timeout_ms: int | None = None) -> None:
        self.expect(self.page.locator("#log li", has_text=text).first).to_be_attached(
            timeout=timeout_ms or self.TIMEOUT_MS)

    def take_control(self) -> None:
        """Open a session, lock, activate: through the buttons, as an operator does."""
        self.click("btn-session")
        self.expect(self.page.locator("#btn-lock")).to_be_enabled(timeout=self.TIMEOUT_MS)
        self.click("btn-lock")
        self.expect(self.page.locator("#btn-activate")).to_be_enabled(timeout=self.TIMEOUT_MS)
        self.click("btn-activate")
        self.shows("st-state", "resting")

    def manual_control(self, on: bool) -> None:
        """The pendant's ManualControl box, waited for until the device says so (the box
        ticks at once; the device's answer comes after)."""
        box = self.page.locator("#manual-control")
        if box.is_checked() != on:
            box.click(timeout=self.TIMEOUT_MS)
        self.shows("st-manual", "teachpendant" if on else "off")

    def joint(self, index: int) -> str:
        return self.page.inner_text(f"#joints .joint:nth-child({index + 1}) .jvalue",
                                    timeout=self.TIMEOUT_MS)

    def close(self) -> None:
        self.context.close()
        assert not self.errors, f"errors in the page: {self.errors}"
