"""Issue 28 item 5, in Debian's headless Chromium on the real backend and a real device server:
path progress counts that add up, a refusal that hides no state, event numbers that fit,
words for people instead of enum names, and no raw transport status reaching the operator.
The page's words module (pure) is also checked under Node.js, which the page's build needs."""
from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from dashboard_support import Page
from landscape.client import Frame, Robot, TagPoint

SRC = Path(__file__).resolve().parents[2] / "supervisor_gui_web" / "frontend" / "src"
TOUR = {"a": (0.3, 0.0, 1.5, 0.0, 1.5, 0.0), "b": (0.5, 0.1, 1.4, 0.0, 1.4, 0.0),
        "c": (0.2, 0.2, 1.3, 0.0, 1.4, 0.0)}
COUNT = re.compile(r"(\d+)/(\d+) tags reached")
# Every text the progress line shows, as it changes (installed in the page).
RECORD_PROGRESS = """() => {
  window.progressTexts = [];
  const box = document.getElementById('path-progress');
  new MutationObserver(() => window.progressTexts.push(box.innerText)).observe(box, { childList: true, subtree: true, characterData: true });
}"""


def _lines(tags: dict) -> str:
    return "\n".join(f"{tag} {' '.join(map(str, q))}" for tag, q in tags.items())


def _counts(page: Page) -> list[tuple[int, int]]:
    texts = page.page.evaluate("() => window.progressTexts")
    return [(int(m[1]), int(m[2])) for text in texts for m in COUNT.finditer(text)]


def test_progress_counts_each_cycle_out_of_the_paths_tags(chromium, dashboard, cell_server):
    page = Page(chromium, dashboard)
    page.take_control()
    page.page.evaluate(RECORD_PROGRESS)
    page.page.fill("#path-name", "loop")
    page.page.fill("#path-points", _lines(TOUR))
    page.click("btn-path-load")
    page.page.fill("#path-cycles", "3")
    page.click("btn-path-run")
    page.shows("path-progress", "done", timeout_ms=90_000)
    counts = _counts(page)
    assert counts and all(reached <= of == 3 for reached, of in counts), counts
    page.shows("path-progress", "cycle 3 of 3, 3/3 tags reached")
    page.close()


def test_progress_of_a_path_stored_before_counts_what_the_device_has(chromium, dashboard,
                                                                      cell_server):
    """The device kept two points of "kept" (another client's); the page teaches a third onto
    it and runs it: it reads the stored points from the device (GetPath), so it counts out of
    the path's three tags, never more."""
    with Robot(cell_server.target, "script") as robot, robot.control(activate=False):
        robot.path_load("kept", [TagPoint(list(TOUR["a"]), tag_name="a"),
                                 TagPoint(list(TOUR["b"]), tag_name="b")], Frame.JOINT)
    page = Page(chromium, dashboard)
    page.take_control()
    page.page.evaluate(RECORD_PROGRESS)
    page.expect(page.page.locator("#path-list")).to_contain_text("kept 2 points (read when previewed)")
    page.page.fill("#path-name", "kept")
    page.page.fill("#teach-tag", "here")
    page.click("btn-teach")
    page.expect(page.page.locator("#path-progress .tag")).to_have_text(["a", "b", "here"])
    page.click("btn-path-run")
    page.shows("path-progress", "done", timeout_ms=60_000)
    counts = _counts(page)
    assert counts and all(reached <= of == 3 for reached, of in counts), counts
    page.shows("path-progress", "done, 3/3 tags reached")
    page.expect(page.page.locator("#path-list")).to_contain_text("3 points, joints; stored on the device")
    page.close()


def _overlap(a: dict, b: dict) -> bool:
    return not (a["x"] + a["width"] <= b["x"] or b["x"] + b["width"] <= a["x"]
                or a["y"] + a["height"] <= b["y"] or b["y"] + b["height"] <= a["y"])


def test_a_refusal_hides_no_state_and_goes_when_dismissed(chromium, dashboard, cell_server):
    page = Page(chromium, dashboard)
    page.take_control()
    page.click("btn-release")   # Resting: refused
    refusal = page.page.locator("#refusal")
    page.expect(refusal).to_be_visible()
    box = refusal.bounding_box()
    for watched in ("#st-state", "#st-lock", "#st-estop", "#st-power", ".status"):
        assert not _overlap(box, page.page.locator(watched).bounding_box()), watched
    page.click("btn-refusal-close")
    page.expect(refusal).to_be_hidden()
    page.click("btn-release")
    page.expect(refusal).to_be_visible()
    refusal.press("Escape")
    page.expect(refusal).to_be_hidden()
    page.log_has("Release")   # the log keeps it
    page.close()


def test_event_numbers_from_ten_up_fit_their_column(chromium, dashboard, cell_server):
    page = Page(chromium, dashboard)
    page.click("btn-session")
    for _ in range(3):   # ten events and more: locked, activated, deactivated, released, ...
        page.expect(page.page.locator("#btn-lock")).to_be_enabled()
        page.click("btn-lock")
        page.expect(page.page.locator("#btn-activate")).to_be_enabled()
        page.click("btn-activate")
        page.shows("st-state", "resting")
        page.click("btn-deactivate")
        page.shows("st-state", "inactive")
        page.click("btn-release")
        page.shows("st-lock", "nobody")
    page.log_has("#12")
    # Every event's number in a column of its own, drawn whole inside the log; the list draws
    # no markers of its own (an <ol>'s "10." was cut by the log's edge).
    numbers = page.page.evaluate("""() => {
        const log = document.getElementById('log');
        const left = log.getBoundingClientRect().left;
        const events = [...log.children].filter((li) => li.dataset.kind !== 'refused');
        return {
            markers: getComputedStyle(log).listStyleType,
            events: events.length,
            shown: events.map((li) => li.querySelector('.seq'))
                .filter((seq) => seq && seq.scrollWidth <= seq.clientWidth && seq.getBoundingClientRect().left >= left)
                .map((seq) => seq.textContent),
        };
    }""")
    assert numbers["markers"] == "none"
    assert len(numbers["shown"]) == numbers["events"] >= 12
    assert "#12" in numbers["shown"]
    page.close()


ENUM_NAME = re.compile(r"\b[A-Z]{2,}_[A-Z_]{2,}\b|\b[a-z]+_[a-z]+_[a-z_]+\b")


def test_units_states_and_modes_are_words(chromium, dashboard, cell_server):
    page = Page(chromium, dashboard)
    page.expect(page.page.locator("#units-linear option")).to_have_text(["m", "mm", "cm", "in", "ft"])
    page.expect(page.page.locator("#units-angular option")).to_have_text(["rad", "°"])
    page.shows("st-units", "m, rad")
    page.take_control()
    page.page.fill("#path-name", "away")
    page.page.fill("#path-points", _lines({"far": (1.2, 0.4, 1.2, 0.0, 1.3, 0.0)}))
    page.click("btn-path-load")
    page.click("btn-path-run")
    page.shows("st-motion", "running a trajectory")
    page.click("btn-stop")
    page.shows("st-motion", "paused")
    page.click("btn-abort")
    page.shows("st-motion", "stopped on command")   # robot_stopped_on_command
    page.shows("st-power", "on")
    page.click("btn-release")                         # refused: its codes in small print only
    page.expect(page.page.locator("#refusal")).to_be_visible()
    shown = page.page.evaluate("""() => {
        const copy = document.body.cloneNode(true);
        copy.querySelectorAll('.codes, script, style').forEach((e) => e.remove());
        return copy.innerText;
    }""")
    assert ENUM_NAME.findall(shown) == []
    page.close()


def test_a_garbled_transport_status_never_reaches_the_operator():
    """What grpc.aio may put in place of the device's status (grpc/grpc#36066), and gRPC's
    words for a server that is not there, read as sentences; the device's own words pass."""
    node = shutil.which("node")
    if node is None:
        pytest.skip("Node.js is absent (the page's build needs it too)")
    script = f"""
      import {{ explain, readable }} from '{SRC / "words.js"}';
      console.log(JSON.stringify([
        explain({{ code: 13, message: 'your session ended: Internal error from Core', details: [] }}),
        readable('failed to connect to all addresses; last error: UNKNOWN: ipv4:127.0.0.1:50051: Failed to connect to remote host: Connection refused'),
        readable('no keep-alive for 2 s'),
      ]));"""
    garbled, refused, own = json.loads(subprocess.run(
        [node, "--input-type=module", "-e", script], capture_output=True, text=True, check=True,
        timeout=30).stdout)
    assert garbled["text"] == ("your session ended: the connection to the device broke off (gRPC "
                               "gave no reason)")
    assert "Internal error from Core" not in garbled["text"]
    assert garbled["codes"] == "INTERNAL"
    assert refused == "the device server at 127.0.0.1:50051 refuses connections (it is not running)"
    assert own == "no keep-alive for 2 s"
