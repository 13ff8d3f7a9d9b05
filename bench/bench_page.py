"""The operator's page in Debian's headless Chromium, as users run it: device servers
(`python -m landscape.server`, real-time cycle process) and the web supervisor in their own
processes. Figures, each beside a baseline from the same run and browser:

- page load to the first drawn arm (navigation start -> first frame showing the arm), beside
  an empty three.js page's first frame;
- click to the first moving frame (Run pressed -> the first frame showing the arm moved),
  beside a bare gRPC client's PathMove -> its first state sample showing the arm moved;
- frames per second of the 3D views while two arms move, as the page draws by default and
  with ?render=full, beside an empty three.js scene drawn flat out.

The browser's state latency beside a bare StreamState client is bench_dashboard.py's.
Prints, no pass/fail. Run: .venv/bin/python bench/bench_page.py [seconds]
"""
from __future__ import annotations

import http.server
import shutil
import sys
import tempfile
import threading
import time
from functools import partial
from pathlib import Path

import grpc
from bench_dashboard import CHROMIUM, CHROMIUM_ARGS, drive_tour, no_chromium, spawn, stop
from common import pct, record

THREE = Path(__file__).resolve().parents[1] / "supervisor_gui_web" / "frontend" / "node_modules" / "three" / "build"
LOADS = 5
CLICKS = 5
# An empty three.js scene, drawn in every animation frame: the browser's own pace.
EMPTY = """<!doctype html><html><body style="margin:0"><canvas id="c" style="width:100vw;height:100vh"></canvas>
<script type="module">
import * as THREE from './three.module.js';
const renderer = new THREE.WebGLRenderer({ canvas: document.getElementById('c'), antialias: false });
renderer.setPixelRatio(devicePixelRatio);
renderer.setSize(innerWidth, innerHeight, false);
const scene = new THREE.Scene(), camera = new THREE.PerspectiveCamera(45, innerWidth / innerHeight, 0.05, 50);
window.frames = 0; window.firstFrameAt = null;
(function loop() { renderer.render(scene, camera); window.frames += 1;
  if (window.firstFrameAt === null) window.firstFrameAt = performance.now(); requestAnimationFrame(loop); })();
</script></body></html>"""


def serve_empty_scene() -> tuple[http.server.ThreadingHTTPServer, str]:
    folder = Path(tempfile.mkdtemp(prefix="bench-page-"))
    for name in ("three.module.js", "three.core.js"):
        shutil.copy(THREE / name, folder / name)
    (folder / "index.html").write_text(EMPTY)
    class Quiet(http.server.SimpleHTTPRequestHandler):
        def log_message(self, *args):
            pass
    server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), partial(Quiet, directory=str(folder)))
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{server.server_address[1]}/"


def signed_in(browser, url: str, token: str):
    context = browser.new_context(viewport={"width": 1440, "height": 900})
    page = context.new_page()
    page.goto(url)
    page.fill("#sign-in-token", token)
    page.click("#btn-sign-in")
    page.wait_for_function("() => window.cellViews && Object.values(window.cellViews).every((v) => v.stats.firstArmAt)",
                           timeout=60_000)
    return context, page


def load_times(context, url: str, empty_url: str) -> tuple[list[float], list[float]]:
    page_ms, empty_ms = [], []
    for _ in range(LOADS):
        tab = context.new_page()
        tab.goto(url)
        page_ms.append(tab.wait_for_function(
            "() => window.cellViews && window.cellViews.arm1.stats.firstArmAt", timeout=60_000).json_value())
        tab.close()
        tab = context.new_page()
        tab.goto(empty_url)
        empty_ms.append(tab.wait_for_function("() => window.firstFrameAt", timeout=60_000).json_value())
        tab.close()
    return page_ms, empty_ms


def click_to_motion(page) -> tuple[list[float], list[float]]:
    """Run pressed on a loaded path, to the first sample that moved the arm in the page, and
    to the first frame that shows it (ms)."""
    page.evaluate("""() => document.getElementById('btn-path-run').addEventListener('click',
        () => { window.clickedAt = performance.now(); }, { capture: true })""")
    samples, frames = [], []
    after = """(kind) => {
        const time = window.cellViews.arm1.stats[kind].find((t) => t > window.clickedAt);
        return time && time - window.clickedAt;
    }"""
    for _ in range(CLICKS):
        page.fill("#path-name", "hop")
        page.click("#btn-path-run")
        frames.append(page.wait_for_function(after, arg="moveFrames", timeout=30_000).json_value())
        samples.append(page.evaluate(after, "moveSamples"))
        page.wait_for_function("() => /done|failed|aborted/.test(document.getElementById('path-progress').innerText)",
                               timeout=60_000)
        page.wait_for_timeout(500)
    return samples, frames


def bare_client_to_motion(target: str, runs: int = CLICKS) -> list[float]:
    """PathMove by a bare gRPC client to its first state sample showing the arm moved (ms)."""
    from landscape.client import Session
    from landscape.v1 import (control_pb2, device_service_pb2_grpc, motion_pb2,
                              state_service_pb2 as pb, state_service_pb2_grpc, types_pb2)
    delays = []
    with grpc.insecure_channel(target) as channel, Session(channel, "bench-bare") as session:
        device = device_service_pb2_grpc.DeviceServiceStub(session.channel)
        session.lock()
        device.Activate(control_pb2.ActivateRequest(), timeout=10)
        for _ in range(runs):
            states = state_service_pb2_grpc.StateServiceStub(channel).StreamState(pb.StreamStateRequest())
            next(states)                        # StreamStarted
            first = next(states).sample
            start = time.perf_counter()
            device.PathMove(motion_pb2.PathMoveRequest(path_name="hop"), timeout=10)
            for reply in states:
                if any(abs(a - b) > 1e-5 for a, b in zip(reply.sample.joint_positions, first.joint_positions)):
                    delays.append((time.perf_counter() - start) * 1000)
                    break
            states.cancel()
            resting = types_pb2.DEVICE_STATE_RESTING
            while device.GetDeviceState(control_pb2.GetDeviceStateRequest()).state != resting:
                time.sleep(0.05)
    with grpc.insecure_channel(target) as channel:   # the session's end powers down, releases
        device = device_service_pb2_grpc.DeviceServiceStub(channel)
        unlocked = types_pb2.DEVICE_STATE_UNLOCKED
        while device.GetDeviceState(control_pb2.GetDeviceStateRequest()).state != unlocked:
            time.sleep(0.05)
    return delays


def frame_rate(tab, seconds: float, counter: str) -> float:
    before = tab.evaluate(counter)
    time.sleep(seconds)
    return (tab.evaluate(counter) - before) / seconds


def load_hop(target: str) -> None:
    """A short two-point path, "hop", there and back."""
    from landscape.client import Frame, Robot, TagPoint
    with Robot(target, "bench-loader") as robot, robot.control(activate=False):
        robot.path_load("hop", [TagPoint([0.3, 0.1, 1.5, 0.0, 1.4, 0.0], tag_name="out"),
                                TagPoint([0.0, 0.0, 1.5708, 0.0, 1.5708, 0.0], tag_name="back")], Frame.JOINT)


def row(name: str, values: list[float], unit: str) -> str:
    if not values:
        return f"{name:<46} no figures"
    return f"{name:<46} {len(values):>3} {pct(values, 50):>9.1f} {max(values):>9.1f} {unit}"


def main() -> None:
    seconds = float(sys.argv[1]) if len(sys.argv) > 1 else 10.0
    if no_chromium():
        return
    from playwright.sync_api import sync_playwright
    from landscape.cell.tokens import make_tokens
    from landscape.client import read_token
    people = Path(tempfile.mkdtemp(prefix="bench-page-people-"))
    tokens = make_tokens(people)
    first, target1 = spawn("landscape.server", "--port", "0", ready="listening on")
    second, target2 = spawn("landscape.server", "--port", "0", ready="listening on")
    dashboard, url = spawn("landscape.supervisor", "--device", f"arm1={target1}", "--device",
                           f"arm2={target2}", "--port", "0", "--sign-in-tokens", str(people),
                           ready="web supervisor on")
    empty, empty_url = serve_empty_scene()
    done = threading.Event()
    drivers = []
    try:
        load_hop(target1)
        with sync_playwright() as p:
            browser = p.chromium.launch(executable_path=CHROMIUM, args=CHROMIUM_ARGS)
            context, page = signed_in(browser, url, read_token(tokens["operator"]))
            loads, empty_loads = load_times(context, url, empty_url)
            page.click("#btn-session")
            page.wait_for_function("() => !document.getElementById('btn-lock').disabled")
            page.click("#btn-lock")
            page.wait_for_function("() => !document.getElementById('btn-activate').disabled")
            page.click("#btn-activate")
            page.wait_for_function("() => /resting/.test(document.getElementById('st-state').innerText)")
            click_samples, clicks = click_to_motion(page)
            page.click("#btn-deactivate")
            page.wait_for_function("() => /inactive/.test(document.getElementById('st-state').innerText)")
            page.click("#btn-release")
            page.wait_for_function("() => /nobody/.test(document.getElementById('st-lock').innerText)")
            page.close()
            bare = bare_client_to_motion(target1)
            drivers = [threading.Thread(target=drive_tour, args=(t, done), daemon=True) for t in (target1, target2)]
            for driver in drivers:
                driver.start()
            time.sleep(3.0)   # both arms under way
            rates = {}
            for mode in ("", "?render=full"):
                tab = context.new_page()
                tab.goto(url + mode)
                tab.wait_for_function("() => window.cellViews && window.cellViews.arm2 && window.cellViews.arm2.stats.firstArmAt",
                                      timeout=60_000)
                time.sleep(2.0)
                for arm in ("arm1", "arm2"):
                    rates[f"{mode or 'default'}, {arm}"] = frame_rate(
                        tab, seconds / 2, f"() => window.cellViews.{arm}.stats.frames")
                tab.close()
            tab = context.new_page()
            tab.goto(empty_url)
            tab.wait_for_function("() => window.firstFrameAt")
            empty_rate = frame_rate(tab, seconds, "() => window.frames")
            browser.close()
    finally:
        done.set()
        for driver in drivers:
            driver.join(timeout=10)
        empty.shutdown()
        stop(dashboard)
        stop(first)
        stop(second)
        shutil.rmtree(people, ignore_errors=True)
    print(f"the operator's page in headless Chromium (software rendering), {LOADS} loads, {CLICKS} clicks")
    print(f"{'figure':<46} {'n':>3} {'p50':>9} {'max':>9}")
    print(row("page load -> first drawn arm", loads, "ms"))
    print(row("  baseline: empty three.js page, first frame", empty_loads, "ms"))
    print(row("click Run -> first sample moving the arm", click_samples, "ms"))
    print(row("click Run -> first frame of the arm moving", clicks, "ms"))
    print(row("  baseline: bare gRPC PathMove -> moved sample", bare, "ms"))
    print(f"3D view, frames per second per arm while two arms move ({seconds:g} s):")
    for mode, rate in rates.items():
        print(f"  page, {mode:<18} {rate:8.1f} /s")
    print(f"  baseline: empty three.js scene, every frame {empty_rate:8.1f} /s")
    record("page load to first drawn arm p50", pct(loads, 50), "ms", baseline=pct(empty_loads, 50),
           baseline_name="empty three.js page's first frame")
    record("click to first moving frame p50", pct(clicks, 50), "ms", baseline=pct(bare, 50),
           baseline_name="bare gRPC PathMove to moved sample")
    record("3D view fps, two arms moving", rates.get("default, arm1", float("nan")), "/s",
           baseline=empty_rate, baseline_name="empty three.js scene", better="higher")


if __name__ == "__main__":
    main()
