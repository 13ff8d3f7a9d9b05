"""The real dashboard backend in a thread of the test process, the people who sign in to it,
and a real Chromium from Debian."""
from __future__ import annotations

import asyncio
import contextlib
import json
import os
import re
import secrets
import signal
import subprocess
import sys
import threading
from concurrent.futures import Future
from dataclasses import dataclass
from pathlib import Path

import aiohttp
import pytest

from landscape.supervisor import DashboardConfig, DeviceTarget, start

CHROMIUM = "/usr/bin/chromium"
# As root, in a sandbox without a network: no sandbox, no background connections, no GPU.
CHROMIUM_ARGS = ["--no-sandbox", "--disable-background-networking", "--disable-gpu",
                 "--disable-component-update", "--disable-sync", "--no-first-run"]


# LANDSCAPE_PAGE_DIST=<a built page> serves that build instead of the package's (to see a new
# page test fail on an older page: build it with `npx vite build --outDir DIR`).
PAGE_DIST = os.environ.get("LANDSCAPE_PAGE_DIST")

# Who may sign in, by role: the names their tokens carry in the folder's files.
PEOPLE = {"viewer": ("vera", "watcher", "supervisor"),
          "operator": ("olga", "operator-1", "owner-page", "watcher-page"),
          "admin": ("ada",)}


@dataclass(frozen=True)
class People:
    """A token folder as `landscape-cell tokens` writes it (`<token> <name>` a line), one
    token per person of PEOPLE. The device servers of a test may use the same folder."""

    folder: Path
    tokens: dict[str, str]     # name -> token

    @classmethod
    def make(cls, folder: Path) -> "People":
        folder.mkdir(parents=True, exist_ok=True)
        tokens = {}
        for role, names in PEOPLE.items():
            lines = []
            for name in names:
                tokens[name] = secrets.token_urlsafe(32)
                lines.append(f"{tokens[name]} {name}\n")
            (folder / f"{role}.tokens").write_text("".join(lines))
        return cls(folder, tokens)

    def token(self, name: str) -> str:
        return self.tokens[name]


def origin_of(url: str) -> str:
    """The origin of a supervisor's URL ("http://127.0.0.1:8080/" -> "http://127.0.0.1:8080")."""
    return url.rstrip("/")


def page_headers(url: str) -> dict[str, str]:
    """What the page's own requests that change something carry."""
    return {"Origin": origin_of(url), "X-Landscape-Request": "page"}


async def signed_in_http(url: str, token: str) -> aiohttp.ClientSession:
    """An HTTP client signed in to the supervisor at `url` (its cookie kept; IP hosts too)."""
    http = aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True))
    reply = await http.post(url + "api/sign-in", json={"token": token}, headers=page_headers(url))
    if reply.status != 200:
        await http.close()
        raise AssertionError(f"sign-in refused: {reply.status} {await reply.text()}")
    return http


DEVICE = "landscape.v1.DeviceService/"
CONNECT = "landscape.v1.SessionService/Connect"
TIMEOUT = 30.0


async def open_page(url: str, token: str):
    """A signed-in HTTP client and its page's WebSocket (from the supervisor's own origin)."""
    http = await signed_in_http(url, token)
    return http, await http.ws_connect(url + "ws", origin=origin_of(url))


class PageClient:
    """The page's side of the WebSocket: numbered calls, and every frame kept for inspection."""

    def __init__(self, ws, http: aiohttp.ClientSession | None = None):
        self.ws = ws
        self.http = http     # the signed-in HTTP client the socket was opened with
        self.frames: list[dict] = []
        self._next = 1

    async def send(self, rpc: str, request=None, *, call_id=None, device="arm1", **extra) -> int:
        call_id = call_id if call_id is not None else self._next
        self._next = max(self._next, call_id) + 1
        body = {"device": device, "rpc": rpc, "id": call_id, **extra}
        if request is not None:
            body["request"] = request
        await self.ws.send_str(json.dumps(body))
        return call_id

    async def until(self, predicate, timeout: float = TIMEOUT) -> dict:
        """The first frame (kept or new) for which predicate holds."""
        for frame in self.frames:
            if predicate(frame):
                return frame
        async with asyncio.timeout(timeout):
            while True:
                message = await self.ws.receive()
                assert message.type is aiohttp.WSMsgType.TEXT, message
                frame = json.loads(message.data)
                self.frames.append(frame)
                if predicate(frame):
                    return frame

    async def answer(self, call_id: int) -> dict:
        return await self.until(lambda f: f.get("id") == call_id and ("reply" in f or "status" in f))

    async def call(self, rpc: str, request=None) -> dict:
        return await self.answer(await self.send(rpc, request))



def run_with_page(server, body, people, devices=None, person="olga", **config):
    """Run body(page, dashboard) against a backend on a free port, within a time limit, the
    page signed in as `person`; its devices (DeviceTargets) default to `server` as arm1."""
    async def main():
        dashboard = await start(DashboardConfig(
            devices=devices or (DeviceTarget("arm1", server.target),), port=0,
            sign_in_tokens=str(people.folder), **config))
        try:
            http, ws = await open_page(dashboard.url, people.token(person))
            async with http, ws:
                await body(PageClient(ws, http), dashboard)
        finally:
            await dashboard.stop()
    asyncio.run(asyncio.wait_for(main(), 120))


class DashboardThread:
    """`python -m landscape.supervisor` as a test runs it: the same app on its own event loop,
    in a thread, on a free loopback port; people sign in with `people`'s tokens."""

    def __init__(self, devices: dict[str, str], people: People, **config):
        self.people = people
        self._loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self._loop.run_forever, name="dashboard", daemon=True)
        self._thread.start()
        targets = tuple(DeviceTarget(name, target) for name, target in devices.items())
        if PAGE_DIST:
            config.setdefault("static_dir", PAGE_DIST)
        self._running = self.run(start(DashboardConfig(
            devices=targets, port=0, sign_in_tokens=str(people.folder), **config)))
        self.url = self._running.url

    def run(self, coroutine, timeout: float = 30.0):
        """Run a coroutine on the dashboard's loop and wait for its result."""
        future: Future = asyncio.run_coroutine_threadsafe(coroutine, self._loop)
        return future.result(timeout)

    def stop(self) -> None:
        self.run(self._running.stop())
        self._loop.call_soon_threadsafe(self._loop.stop)
        self._thread.join(timeout=10)


class SpawnedDashboard:
    """`python -m landscape.supervisor` in a process of its own (so a test can stop, starve
    or kill it), on a free loopback port; people sign in with `people`'s tokens."""

    def __init__(self, devices: dict[str, str], people: People, *args: str):
        self.people = people
        argv = [sys.executable, "-m", "landscape.supervisor", "--port", "0",
                "--sign-in-tokens", str(people.folder), *args]
        for name, target in devices.items():
            argv += ["--device", f"{name}={target}"]
        self.process = subprocess.Popen(argv, stdout=subprocess.PIPE,
                                        stderr=subprocess.DEVNULL, text=True)
        line = self.process.stdout.readline()
        if not line.startswith("web supervisor on "):
            self.stop()
            raise AssertionError(f"the supervisor did not start: {line!r}")
        self.url = line.split()[-1]
        self.pid = self.process.pid

    def stop(self) -> int:
        if self.process.poll() is None:
            self.process.send_signal(signal.SIGCONT)   # a stopped process cannot take SIGTERM
            self.process.terminate()
        return self.process.wait(timeout=30)


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
    """One browser tab on the dashboard, as a person uses it: signed in through the form with
    their token, buttons by their ids, what the page shows by its ids. Every wait has a
    timeout; errors in the page fail the test."""

    TIMEOUT_MS = 30_000

    def __init__(self, chromium, dashboard: DashboardThread, name: str = "olga", query: str = "",
                 scale: float = 1):
        self.context = chromium.new_context(viewport={"width": 1400, "height": 1000},
                                            device_scale_factor=scale)
        self.page = self.context.new_page()
        self.errors: list[str] = []
        self.page.on("pageerror", lambda error: self.errors.append(str(error)))
        from playwright.sync_api import expect
        self.expect = expect
        self.page.goto(dashboard.url + query)
        self.sign_in(dashboard.people.token(name))
        expect(self.page.locator("#person")).to_have_text(
            f"{name} ({next(r for r, names in PEOPLE.items() if name in names)})")
        # ("connected" alone: the older page's words, for LANDSCAPE_PAGE_DIST)
        expect(self.page.locator("#connection")).to_have_text(re.compile("^(supervisor )?connected$"),
                                                              timeout=self.TIMEOUT_MS)
        expect(self.page.locator("#joints .joint")).to_have_count(6, timeout=self.TIMEOUT_MS)

    def sign_in(self, token: str) -> None:
        """Through the form, as a person does (the page reloads, signed in)."""
        self.expect(self.page.locator("#sign-in")).to_be_visible(timeout=self.TIMEOUT_MS)
        self.page.fill("#sign-in-token", token)
        self.page.click("#btn-sign-in")
        self.expect(self.page.locator("#app")).to_be_visible(timeout=self.TIMEOUT_MS)

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
        self.shows("st-manual", "teach pendant" if on else "off")

    def status(self, field: str, device: str = "arm1"):
        """A field of a device's row in the status bar (state, lock, power, estop, alarms,
        speed, fresh)."""
        return self.page.locator(f".status-row[data-device='{device}'] [data-field='{field}']")

    def in_view(self, locator) -> bool:
        """Whether the element is drawn whole inside the window."""
        box = locator.bounding_box()
        size = self.page.viewport_size
        return bool(box) and box["x"] >= 0 and box["y"] >= 0 and \
            box["x"] + box["width"] <= size["width"] + 0.5 and box["y"] + box["height"] <= size["height"] + 0.5

    def fold_and_scroll_to_the_end(self) -> None:
        """Every foldable part folded, then opened again and everything scrolled to its end."""
        self.page.evaluate("""() => {
            document.querySelectorAll('details').forEach((d) => { d.open = false; });
            document.querySelectorAll('details').forEach((d) => { d.open = true; });
            for (const box of [document.scrollingElement, ...document.querySelectorAll('.panels, .log')]) {
                box.scrollTop = box.scrollHeight;
            }
        }""")

    def joint(self, index: int) -> str:
        return self.page.inner_text(f"#joints .joint:nth-child({index + 1}) .jvalue",
                                    timeout=self.TIMEOUT_MS)

    def screenshot(self, name: str) -> Path:
        """A picture of the page under var/screenshots (not in git), for the test's record."""
        path = Path(__file__).resolve().parents[2] / "var" / "screenshots" / f"{name}.png"
        path.parent.mkdir(parents=True, exist_ok=True)
        self.page.screenshot(path=str(path))
        return path

    def close(self) -> None:
        self.context.close()
        assert not self.errors, f"errors in the page: {self.errors}"
