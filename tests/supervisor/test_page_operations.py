"""Issue 28 item 2 (what operators asked for), in Debian's headless Chromium on the real backend
and real device servers: a move to a point previewed by a ghost arm, joint and tool plots
with readable axes, a speed slider that shows the device's own speed, the paths the page
knows previewed in 3D before they run, and the recorder (downloads not offered yet, and said
so). On a cell of one arm and of two. Screenshots go to var/screenshots (not in git)."""
from __future__ import annotations

import json
import shutil
import subprocess
from pathlib import Path

import numpy as np
import pytest

from dashboard_support import DashboardThread, Page
from landscape.client import Frame, Robot, TagPoint
from landscape.server.config import SecurityConfig
from landscape.server.device.states import State
from support import start_server, wait_until

SRC = Path(__file__).resolve().parents[2] / "supervisor_gui_web" / "frontend" / "src"
GOAL = (0.4, 0.1, 1.4, 0.0, 1.4, 0.0)
GHOST = """(device) => {
    const arm = window.armViews[device];
    return {visible: arm.ghost.visible, joints: arm.jointNames.map((n) => arm.ghost.joints[n].angle)};
}"""


def _joints(server) -> np.ndarray:
    return np.array(server.device.feedback().position)


def _ghost(page: Page, device: str = "arm1") -> dict:
    page.page.wait_for_function(f"() => window.armViews['{device}'].ghost.visible", timeout=30_000)
    return page.page.evaluate(GHOST, device)


def _move_in_joints(page: Page, server, device: str) -> None:
    before = _joints(server)
    for i, value in enumerate(GOAL):
        page.page.fill(f"#move-v{i}", str(value))
    page.shows("move-preview", "Ghost arm: the goal as the device solves it")
    ghost = _ghost(page, device)
    assert ghost["joints"] == pytest.approx(GOAL, abs=1e-9)      # the goal, before any move
    assert _joints(server) == pytest.approx(before, abs=1e-6)    # nothing moved
    page.screenshot(f"move-ghost-{device}")
    page.click("btn-move")
    page.shows("st-state", "moving")
    page.shows("st-state", "resting", timeout_ms=60_000)
    wait_until(lambda: _joints(server) == pytest.approx(GOAL, abs=2e-3), timeout=10)


def test_move_to_a_joint_goal_previewed_by_the_ghost_arm(chromium, dashboard, cell_server):
    page = Page(chromium, dashboard)
    page.take_control()
    _move_in_joints(page, cell_server, "arm1")
    page.close()


def test_move_to_a_cartesian_goal_from_the_current_pose(chromium, dashboard, cell_server):
    page = Page(chromium, dashboard)
    page.take_control()
    page.page.select_option("#move-frame", "REFERENCE_FRAME_BASE_CARTESIAN_FRAME")
    page.click("btn-move-from-current")
    page.expect(page.page.locator("#move-v2")).not_to_have_value("", timeout=10_000)
    z = float(page.page.input_value("#move-v2"))
    page.page.fill("#move-v2", f"{z - 0.05:.4f}")                 # 5 cm down
    page.shows("move-preview", "the goal as the device solves it")   # SolvePose
    # The preview said so for the goal "from current" already: the ghost is the answer to the
    # edit (5 cm down) once it stands elsewhere than the arm (it stood at the arm under load).
    before = _joints(cell_server)
    wait_until(lambda: np.abs(np.array(_ghost(page)["joints"]) - before).max() > 0.005,
               timeout=30)
    ghost = _ghost(page)
    page.click("btn-move")
    page.shows("st-state", "moving")
    page.shows("st-state", "resting", timeout_ms=60_000)
    # The arm went where the ghost stood, and its tool tip 5 cm down.
    wait_until(lambda: _joints(cell_server) == pytest.approx(ghost["joints"], abs=3e-3), timeout=10)
    with Robot(cell_server.target, "reader") as robot:
        assert robot.get_robot_position().world_position.z == pytest.approx(z - 0.05, abs=1e-3)
    page.close()


def test_a_goal_the_device_would_refuse_has_no_ghost_and_says_why(chromium, dashboard,
                                                                   cell_server):
    """Issue 28: the ghost is the device's answer (SolvePose); a pose beyond reach gets none,
    and the device's reason, before anything is sent to move."""
    page = Page(chromium, dashboard)
    page.page.select_option("#move-frame", "REFERENCE_FRAME_BASE_CARTESIAN_FRAME")
    page.click("btn-move-from-current")
    page.shows("move-preview", "the goal as the device solves it")
    page.page.fill("#move-v2", "5")                               # 5 m up: beyond reach
    page.shows("move-preview", "No preview: the device would refuse this move:")
    assert not page.page.evaluate(GHOST, "arm1")["visible"]
    assert cell_server.device.state is State.UNLOCKED              # asked as a viewer may
    page.close()


def test_the_move_form_moves_the_chosen_arm_of_two(chromium, two_arm_dashboard, two_arm_servers):
    first, second = two_arm_servers
    page = Page(chromium, two_arm_dashboard)
    page.page.locator(".status-row[data-device='arm2'] .arm-name").click()
    page.shows("panels-device", "arm2")
    page.take_control()
    still = _joints(first)
    _move_in_joints(page, second, "arm2")
    assert not page.page.evaluate("() => window.armViews.arm1.ghost.visible")
    assert _joints(first) == pytest.approx(still, abs=1e-6)
    assert first.device.state is State.UNLOCKED
    page.close()


# Each plot scrolled into view (plots off screen are not drawn), then what it drew.
SHOW_PLOTS = """async () => {
    for (const p of window.livePlots.plots) {
        p.element.scrollIntoView();
        await new Promise((resolve) => setTimeout(resolve, 600));
    }
}"""
PLOTS = """() => Object.fromEntries(window.livePlots.plots.map((p) => [p.name, {
    points: p.plot.data[0].length,
    ticks: p.plot.axes[1]._values,          // the y axis's labels as uPlot drew them
    unit: document.getElementById(`plot-${p.name}-unit`).textContent,
}]))"""


def test_joint_and_tool_plots_with_units_and_distinct_tick_labels(chromium, dashboard, cell_server):
    page = Page(chromium, dashboard)
    page.take_control()
    page.page.wait_for_timeout(1500)     # a second or so of a still arm: flat lines
    page.page.evaluate(SHOW_PLOTS)
    plots = page.page.evaluate(PLOTS)
    assert set(plots) == {"joints", "velocities", "tip", "force", "following"}
    for name, plot in plots.items():
        assert plot["points"] > 5, name
        assert len(set(plot["ticks"])) == len(plot["ticks"]) >= 2, (name, plot["ticks"])
    assert (plots["joints"]["unit"], plots["velocities"]["unit"], plots["tip"]["unit"]) == ("rad", "rad/s", "m")
    page.page.fill("#jog-speed", "30")
    page.manual_control(True)
    page.page.locator("[data-testid='jog-J1+']").hover()
    page.page.mouse.down()
    page.page.wait_for_timeout(800)
    page.page.mouse.up()
    page.page.locator("#plot-velocities").scroll_into_view_if_needed()
    page.page.wait_for_timeout(600)
    moving = page.page.evaluate(PLOTS)
    assert any(abs(float(v)) > 0 for v in moving["velocities"]["ticks"] if v != "0")
    page.screenshot("plots")
    page.close()


def test_tick_labels_say_each_step_once():
    node = shutil.which("node")
    if node is None:
        pytest.skip("Node.js is absent (the page's build needs it too)")
    script = f"""
      import {{ tickText }} from '{SRC / "units.js"}';
      const ticks = (values, step) => values.map((v) => tickText(v, step));
      console.log(JSON.stringify([ticks([-0.0002, -0.0001, 0, 0.0001], 0.0001),
        ticks([0, 0.25, 0.5, 0.75], 0.25), ticks([-2, 0, 2], 2), ticks([-1e-17, 0.5], 0.5)]));"""
    small, quarters, twos, zero = json.loads(subprocess.run(
        [node, "--input-type=module", "-e", script], capture_output=True, text=True, check=True,
        timeout=30).stdout)
    assert small == ["-0.0002", "-0.0001", "0.0000", "0.0001"]
    assert quarters == ["0.00", "0.25", "0.50", "0.75"]
    assert twos == ["-2", "0", "2"]
    assert zero == ["0.0", "0.5"]                                  # never "-0.0"


def test_the_speed_slider_shows_the_devices_speed_and_sets_it(chromium, dashboard, cell_server):
    page = Page(chromium, dashboard)
    page.expect(page.page.locator("#speed")).to_have_value("25")
    with Robot(cell_server.target, "script") as robot, robot.control(activate=False):
        robot.set_speed(80)                                        # behind the page's back
    page.expect(page.page.locator("#speed")).to_have_value("80", timeout=10_000)
    page.shows("speed-device", "device: 80 %")
    page.expect(page.status("speed")).to_have_text("speed 80 %")
    page.take_control()
    page.page.fill("#speed", "40")                                 # the slider let go at 40
    page.expect(page.status("speed")).to_have_text("speed 40 %", timeout=10_000)
    with Robot(cell_server.target, "reader") as robot:
        assert robot.get_velocities().percent_velocity == pytest.approx(40)
    page.page.fill("#speed-typed", "250")
    page.click("btn-speed")                                        # refused: shows the device's
    page.shows("refusal-text", "SetSpeed refused")
    page.expect(page.page.locator("#speed-typed")).to_have_value("40", timeout=10_000)
    page.expect(page.page.locator("#speed")).to_have_value("40")
    page.close()


def _dots(page: Page, device: str = "arm1") -> int:
    return page.page.evaluate(
        f"() => window.armViews['{device}'].pathGroup.children.filter((c) => c.isMesh).length")


def test_paths_are_listed_and_previewed_in_3d_before_they_run(chromium, two_arm_dashboard,
                                                              two_arm_servers):
    first, _ = two_arm_servers
    page = Page(chromium, two_arm_dashboard)
    page.take_control()
    page.shows("path-list-empty", "none yet")
    for name, lines in (("tour", "p1 0.6 0.2 1.4 0 1.4 0\np2 1.2 0.4 1.2 0 1.3 0\np3 -0.6 0.3 1.3 0.5 1.2 0"),
                        ("short", "s1 0.3 0 1.5 0 1.5 0")):
        page.page.fill("#path-name", name)
        page.page.fill("#path-points", lines)
        page.click("btn-path-load")
        page.expect(page.page.locator("#path-list li", has_text=name)).to_contain_text("points, joints")
    page.expect(page.page.locator("#path-list li")).to_have_count(2)
    still = _joints(first)
    page.page.locator("#path-list .path-preview", has_text="tour").click()
    page.page.wait_for_function("() => window.armViews.arm1.ghost.visible", timeout=10_000)
    assert _dots(page) == 3
    ghost = page.page.evaluate(GHOST, "arm1")["joints"]
    assert ghost == pytest.approx([0.6, 0.2, 1.4, 0, 1.4, 0], abs=1e-9)   # at its first point
    assert _joints(first) == pytest.approx(still, abs=1e-6)               # a preview moves nothing
    page.screenshot("path-preview")
    page.page.locator("#path-list .path-preview", has_text="short").click()
    page.page.wait_for_function("() => window.armViews.arm1.pathGroup.children.filter((c) => c.isMesh).length === 1")
    page.click("btn-path-run")
    page.shows("path-progress", "run ", timeout_ms=10_000)
    page.shows("path-progress", "done, 1/1 tags reached", timeout_ms=60_000)
    # The other arm knows none of them.
    page.page.locator(".status-row[data-device='arm2'] .arm-name").click()
    page.expect(page.page.locator("#path-list li")).to_have_count(0)
    assert _dots(page) == 0 and _dots(page, "arm2") == 0
    page.close()


def test_the_devices_stored_paths_are_listed_and_read_for_the_preview(chromium, dashboard,
                                                                       cell_server):
    """Issue 28: the list is the device's (ListPaths), whoever stored the path: a script's path
    is listed with its count of points, and its preview reads the points from the device
    (GetPath, resolved to joints) and stands the ghost at the first; a path another client
    clears leaves the list when the panel is opened again."""
    first, second = [0.5, -0.2, 1.3, 0, 1.2, 0], [0.9, 0.1, 1.1, 0.2, 1.0, 0]
    with Robot(cell_server.target, "script") as robot, robot.control(activate=False):
        robot.path_load("theirs", [TagPoint(first, tag_name="p1"), TagPoint(second)],
                        Frame.JOINT)
    page = Page(chromium, dashboard)
    theirs = page.page.locator("#path-list li", has_text="theirs")
    page.expect(theirs).to_contain_text("2 points (read when previewed), joints; stored on the device")
    page.expect(page.page.locator("#path-list-source")).to_contain_text("stored on the device")
    still = _joints(cell_server)
    theirs.locator(".path-preview").click()
    page.expect(theirs).to_contain_text("2 points, joints; stored on the device")
    page.page.wait_for_function("() => window.armViews.arm1.ghost.visible", timeout=10_000)
    assert _dots(page) == 2
    assert _ghost(page)["joints"] == pytest.approx(first, abs=1e-9)
    assert _joints(cell_server) == pytest.approx(still, abs=1e-6)         # a preview moves nothing
    page.expect(page.page.locator("#path-progress .tag")).to_have_text(["p1"])
    with Robot(cell_server.target, "script") as robot, robot.control(activate=False):
        robot.path_clear_path("theirs")
    panel = page.page.locator("details.panel > summary", has_text="Paths")
    panel.click()   # folded, then opened: the list is read again
    panel.click()
    page.expect(theirs).to_have_count(0)
    page.close()


def test_the_recorder_runs_and_its_recording_and_the_audit_log_download(chromium, people,
                                                                          tmp_path):
    """Issue 28: the recorder stores an MCAP file on the device; an operator downloads it
    (RecordingService.FetchRecording, checked against its SHA-256), an admin the audit log
    (AuditService.ReadAuditLog), which names the operator's calls and its own; the audit log
    is not an operator's."""
    server = start_server(lockstep_pace=1.0,
                          security=SecurityConfig(audit_log=str(tmp_path / "audit.log")))
    dashboard = DashboardThread({"arm1": server.target}, people)
    try:
        page = Page(chromium, dashboard)
        page.page.locator("details.panel > summary", has_text="Recordings").click()
        assert page.page.locator("#btn-recorder-start").is_disabled()   # the lock holder's
        assert page.page.locator("#btn-download-audit").is_disabled()   # an admin's
        page.take_control()
        for action, said in (("start", "recording"), ("stop", "stopped"), ("store", "")):
            page.click(f"btn-recorder-{action}")
            page.shows("recorder-result", f"arm1: {said}")
        with page.page.expect_download() as download:
            page.click("btn-download-recording")
        page.shows("download-result", "saved")
        assert download.value.suggested_filename.startswith("arm1-")
        assert Path(download.value.path()).read_bytes().startswith(b"\x89MCAP0\r\n")
        page.close()
        admin = Page(chromium, dashboard, name="ada")
        admin.page.locator("details.panel > summary", has_text="Recordings").click()
        with admin.page.expect_download() as download:
            admin.click("btn-download-audit")
        admin.shows("download-result", "the audit log (audit.log)")
        records = [json.loads(line) for line in Path(download.value.path()).read_text().splitlines()]
        assert any(r.get("for") == "olga" and r["rpc"].endswith("/Lock") for r in records), records
        assert records[-1]["rpc"].endswith("/ReadAuditLog") and records[-1]["for"] == "ada"
        admin.close()
    finally:
        dashboard.stop()
        server.stop(grace=None)
