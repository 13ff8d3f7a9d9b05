"""The dashboard end to end: headless Chromium (Debian's) on the real backend, on a real device
server with the simulated arm. Everything is done through the page's buttons and read from what
the page shows, then checked against the server."""
from __future__ import annotations

import os
import re
import shutil
import time
from pathlib import Path

import pytest

from dashboard_support import Page
from landscape.server.device.states import State
from support import wait_until

ROOT = Path(__file__).resolve().parents[2]
# Each run's picture goes to var/ (not in git); LANDSCAPE_SCREENSHOT_TO_DOCS=1 copies it over
# the README's docs/dashboard.png.
SCREENSHOT = ROOT / "var" / "screenshots" / "dashboard.png"
README_PICTURE = ROOT / "docs" / "dashboard.png"
# Joint values (rad) of a path over the table, the tool tip 0.75 m or more above the floor.
PATH = {"p1": (0.6, 0.2, 1.4, 0.0, 1.4, 0.0), "p2": (1.2, 0.4, 1.2, 0.0, 1.3, 0.0),
        "p3": (-0.6, 0.3, 1.3, 0.5, 1.2, 0.0), "p4": (-1.2, 0.1, 1.5, 0.0, 1.4, 0.8)}


def path_lines() -> str:
    return "\n".join(f"{tag} {' '.join(map(str, q))}" for tag, q in PATH.items())


def test_lock_and_activate_through_the_buttons(chromium, dashboard, cell_server):
    page = Page(chromium, dashboard, name="operator-1")
    assert page.page.locator("#btn-activate").is_disabled()   # no lock yet: watching
    page.take_control()
    assert cell_server.device.state is State.RESTING
    page.shows("st-lock", "operator-1")
    page.shows("role", "commanding")
    page.log_has("activated")
    page.expect(page.page.locator(".cell-view[data-device=arm1] .scene-note")).to_contain_text(
        "TX90 in cell “default”")   # the world from the device
    page.close()


def test_path_run_reaches_every_tag_in_the_log(chromium, dashboard, cell_server):
    page = Page(chromium, dashboard, query="?render=full")   # a sharp picture for the README
    page.take_control()
    page.page.fill("#speed-typed", "30")
    page.click("btn-speed")
    page.shows("st-speed", "30 %")
    page.page.fill("#path-name", "tour")
    page.page.fill("#path-points", path_lines())
    page.click("btn-path-load")
    page.expect(page.page.locator("#path-progress .tag")).to_have_count(len(PATH), timeout=30_000)
    page.click("btn-path-run")
    page.shows("st-state", "moving")
    # A tag or more reached (exactly one would be a moment a loaded machine's polling may miss).
    page.expect(page.page.locator("#path-progress .tag.reached").first).to_be_attached(
        timeout=40_000)
    # During the run, the arm in its cell, the path drawn, the first tag reached: for the README.
    SCREENSHOT.parent.mkdir(parents=True, exist_ok=True)
    page.page.screenshot(path=str(SCREENSHOT))
    if os.environ.get("LANDSCAPE_SCREENSHOT_TO_DOCS") == "1":
        shutil.copyfile(SCREENSHOT, README_PICTURE)
    page.shows("path-progress", "done", timeout_ms=60_000)
    for index, tag in enumerate(PATH):
        page.log_has(f"tag {tag} (#{index})")
    page.expect(page.page.locator("#path-progress .tag.reached")).to_have_count(len(PATH))
    assert cell_server.device.state is State.RESTING
    page.close()


def test_estop_release_asks_the_lock_holder_and_the_dialog_answers(chromium, dashboard, cell_server):
    page = Page(chromium, dashboard)
    page.take_control()
    page.click("estop-arm1")
    page.shows("st-state", "error")
    page.shows("st-estop", "PRESSED")
    page.click("btn-estop-release")
    dialog = page.page.locator("#rsvp")
    page.expect(dialog).to_be_visible(timeout=30_000)
    page.shows("rsvp-text", "reset now?")
    countdown = int(page.text("rsvp-countdown"))
    assert 0 < countdown <= 30
    page.page.click("#rsvp-choices button[data-choice='reset']")
    page.expect(dialog).to_be_hidden(timeout=30_000)
    page.shows("st-state", "inactive")   # reset, still holding the lock
    page.log_has("answered reset")
    wait_until(lambda: cell_server.device.state is State.INACTIVE, timeout=15)
    page.close()


def test_a_refused_command_shows_the_servers_code_and_message(chromium, dashboard, cell_server):
    page = Page(chromium, dashboard)
    page.take_control()
    page.page.fill("#speed-typed", "250")   # out of range: the server judges, not the page
    page.click("btn-speed")
    page.shows("refusal", "SetSpeed")
    refusal = page.text("refusal")
    assert "OUT_OF_RANGE PARAM_OUT_OF_RANGE ret_code -3" in refusal
    page.log_has("refused: arm1 SetSpeed")
    page.click("btn-release")   # Resting: Release is valid in Inactive only
    page.shows("refusal-text", "arm1: Release refused: Release is not valid in state resting")
    page.shows("refusal-codes", "FAILED_PRECONDITION WRONG_STATE ret_code -1")
    assert cell_server.device.state is State.RESTING   # nothing changed
    page.close()


def test_a_second_browser_watches_live_and_cannot_command(chromium, dashboard, cell_server):
    owner = Page(chromium, dashboard, name="owner-page")
    watcher = Page(chromium, dashboard, name="watcher-page")
    owner.take_control()
    watcher.shows("st-lock", "owner-page")
    watcher.shows("role", "held by owner-page")
    for button in ("btn-activate", "btn-path-run", "btn-speed", "btn-release"):
        locator = watcher.page.locator(f"#{button}")
        assert locator.is_disabled(), button
        assert "held by owner-page" in locator.get_attribute("title")
    before = watcher.joint(0)
    owner.page.fill("#path-points", "p1 " + " ".join(map(str, PATH["p1"])))
    owner.click("btn-path-load")
    owner.click("btn-path-run")
    watcher.expect(watcher.page.locator("#joints .joint:nth-child(1) .jvalue")).not_to_have_text(
        before, timeout=30_000)
    # The state went to moving: in the watcher's log, which stays (on a busy machine the
    # path may be done before the watcher's state cell is looked at).
    watcher.shows("log", "resting → moving")
    # What the watcher may press is refused by the server, with its reason.
    watcher.click("btn-session")
    watcher.expect(watcher.page.locator("#btn-lock")).to_be_enabled(timeout=30_000)
    watcher.click("btn-lock")
    watcher.shows("refusal-text", "arm1: Lock refused: the device is locked by owner-page")
    watcher.shows("refusal-codes", "FAILED_PRECONDITION")
    owner.shows("path-progress", "done", timeout_ms=60_000)
    watcher.close()
    owner.close()


def test_jog_a_joint_from_the_pendant(chromium, dashboard, cell_server):
    page = Page(chromium, dashboard)
    page.take_control()
    page.manual_control(True)
    before = cell_server.device.feedback().position[0]
    shown = page.joint(0)
    button = page.page.locator("[data-testid='jog-J1+']")
    button.hover()
    page.page.mouse.down()
    page.page.wait_for_timeout(600)
    page.page.mouse.up()
    page.expect(page.page.locator("#joints .joint:nth-child(1) .jvalue")).not_to_have_text(shown, timeout=5_000)
    after = cell_server.device.feedback().position[0]
    assert after > before + 0.005
    # The page catches up with the arm's final value (it shows state a few times a second).
    deadline = time.monotonic() + 10
    while abs((value := float(re.match(r"-?[\d.]+", page.joint(0)).group())) - after) > 0.01:
        assert time.monotonic() < deadline, (value, after)
        page.page.wait_for_timeout(100)
    page.close()
