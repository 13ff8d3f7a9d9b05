"""The dashboard's other panels end to end, in Debian's headless Chromium on the real backend
and a real device server: another client's path run followed tag by tag, world-frame points
drawn where the device's world frame puts them, the Cartesian jog, teaching, tools, digital
I/O, and a person's commands reaching a device that uses tokens with the person's own token,
recorded under their name."""
from __future__ import annotations

import json
import math

import numpy as np
import pytest
from scipy.spatial.transform import Rotation

from dashboard_support import DashboardThread, Page
from landscape.client import Frame, Pose, Robot, TagPoint
from landscape.server.config import SecurityConfig
from landscape.server.device.states import State
from support import start_server, wait_until

HOME = [0.0, 0.0, 1.5708, 0.0, 1.5708, 0.0]


def _pose_matrix(pose: Pose) -> np.ndarray:
    matrix = np.eye(4)
    matrix[:3, :3] = Rotation.from_euler("xyz", [pose.roll, pose.pitch, pose.yaw]).as_matrix()
    matrix[:3, 3] = [pose.x, pose.y, pose.z]
    return matrix


def _tip(server) -> np.ndarray:
    """The tool tip (x, y, z) in the world frame, m, as the device reports it."""
    with Robot(server.target, "test-reader") as robot:
        p = robot.get_robot_position().world_position
    return np.array([p.x, p.y, p.z])


def _hold(page: Page, testid: str, ms: int) -> None:
    page.page.locator(f"[data-testid='{testid}']").hover()
    page.page.mouse.down()
    page.page.wait_for_timeout(ms)
    page.page.mouse.up()


def _open_panel(page: Page, title: str) -> None:
    page.page.locator("details.panel > summary", has_text=title).click()


def test_another_clients_path_run_is_followed_tag_by_tag(chromium, dashboard, cell_server):
    """The run of a path the page did not load: its points read from the device (GetPath),
    so its tags count out of the path's."""
    page = Page(chromium, dashboard)
    tags = [TagPoint([0.3, 0.0, 1.5, 0.0, 1.5, 0.0], tag_name="near"),
            TagPoint([0.6, 0.1, 1.4, 0.0, 1.4, 0.0], tag_name="far")]
    with Robot(cell_server.target, "script") as robot, robot.control():
        robot.path_load("visit", tags, Frame.JOINT)
        run = robot.path_move("visit")
        run.wait(timeout=60)
    page.shows("path-progress", f"run {run.command_id} of visit: done, 2/2 tags reached")
    reached = page.page.locator("#path-progress .tag.reached")
    page.expect(reached).to_have_text(["near", "far"])
    page.close()


def test_world_frame_points_are_drawn_through_the_devices_world_frame(chromium, dashboard,
                                                                        cell_server):
    world = Pose(x=0.1, y=-0.05, z=0.02, yaw=0.3)   # the world frame in the base frame
    with Robot(cell_server.target, "setter") as robot, robot.control(activate=False):
        robot.set_world_cartesian_frame(world)
    in_base = _pose_matrix(world)
    down = Rotation.from_euler("xyz", [math.pi, 0, 0]).as_matrix()   # the tool pointing down
    goals = np.array([[0.55, 0.1, 0.6], [0.5, -0.15, 0.55]])          # tip positions, base
    lines = []
    for index, goal in enumerate(goals):   # the same points in the world frame
        point = np.linalg.inv(in_base) @ [*goal, 1.0]
        rpy = Rotation.from_matrix(in_base[:3, :3].T @ down).as_euler("xyz")
        lines.append(f"w{index} " + " ".join(f"{v:.6f}" for v in (*point[:3], *rpy)))
    page = Page(chromium, dashboard)
    page.take_control()
    page.page.select_option("#path-frame", "REFERENCE_FRAME_WORLD_CARTESIAN_FRAME")
    page.page.fill("#path-name", "in-world")
    page.page.fill("#path-points", "\n".join(lines))
    page.click("btn-path-load")
    page.expect(page.page.locator("#path-progress .tag")).to_have_count(2, timeout=30_000)
    dots = "window.armViews.arm1.pathGroup.children.filter((c) => c.isMesh).map((c) => c.position.toArray())"
    page.page.wait_for_function(f"{dots}.length === 2", timeout=30_000)
    drawn = np.array(page.page.evaluate(dots))
    assert drawn == pytest.approx(goals, abs=1e-4)   # in the base frame, where the arm goes
    page.close()


def test_a_cartesian_jog_moves_the_tool_tip_along_the_axis(chromium, dashboard, cell_server):
    page = Page(chromium, dashboard)
    page.take_control()
    page.manual_control(True)
    page.page.select_option("#jog-frame", "REFERENCE_FRAME_BASE_CARTESIAN_FRAME")
    before = _tip(cell_server)
    _hold(page, "jog-Z+", 800)
    wait_until(lambda: cell_server.device.state is State.RESTING, timeout=10)
    moved = _tip(cell_server) - before
    assert moved[2] > 0.005                                   # up
    assert np.hypot(moved[0], moved[1]) < 0.2 * moved[2]      # and not sideways
    page.close()


def test_teach_stores_the_current_poses_as_a_path_that_then_runs(chromium, dashboard,
                                                                 cell_server):
    page = Page(chromium, dashboard)
    page.take_control()
    page.page.fill("#path-name", "taught")
    taught = []
    page.manual_control(True)
    for jog in ("jog-J1+", "jog-J2-"):
        _hold(page, jog, 500)
        wait_until(lambda: cell_server.device.state is State.RESTING, timeout=10)
        page.page.wait_for_timeout(500)   # the page shows the arm where it came to rest
        taught.append(cell_server.device.feedback().position.copy())
        page.click("btn-teach")
        page.expect(page.page.locator("#path-progress .tag")).to_have_count(len(taught),
                                                                           timeout=30_000)
    page.expect(page.page.locator("#path-progress .tag")).to_have_text(["t1", "t2"])
    page.manual_control(False)   # paths do not run under manual control
    with Robot(cell_server.target, "test-reader") as robot:
        assert robot.get_robot_position().joint_position == pytest.approx(taught[1], abs=1e-3)
    page.click("btn-path-run")
    page.shows("path-progress", "done, 2/2 tags reached", timeout_ms=60_000)
    assert cell_server.device.feedback().position == pytest.approx(taught[1], abs=2e-3)
    page.close()


@pytest.fixture
def fast_dashboard(server, people):
    """The backend on a lock-step server that runs flat out: a tool change in seconds."""
    running = DashboardThread({"arm1": server.target}, people)
    yield running
    running.stop()


def test_tools_get_close_open_and_put_from_the_panel(chromium, fast_dashboard, server):
    page = Page(chromium, fast_dashboard)
    page.take_control()
    _open_panel(page, "Tools")
    page.expect(page.page.locator("#tool-id option")).to_have_text(["gripper", "vacuum"])
    page.page.select_option("#tool-id", "gripper")
    page.click("btn-tool-get")
    page.shows("st-tool", "gripper open", timeout_ms=60_000)
    assert server.device.collisions.mounted == "gripper"
    page.click("btn-tool-close")
    page.shows("st-tool", "gripper closed")
    page.click("btn-tool-open")
    page.shows("st-tool", "gripper open")
    page.click("btn-tool-put")
    page.shows("st-tool", "none", timeout_ms=60_000)
    assert server.device.collisions.mounted is None
    page.close()


def test_the_io_panel_shows_bits_by_name_and_toggles_an_output(chromium, dashboard,
                                                               cell_server):
    page = Page(chromium, dashboard)
    _open_panel(page, "Digital I/O")
    page.click("btn-io-list")
    lamp = page.page.locator("#io button.bit", has_text="lamp_green")
    page.expect(lamp).to_be_disabled(timeout=30_000)   # watching: outputs need the lock
    page.expect(page.page.locator("#io .bit", has_text="door_closed")).to_have_class(
        "bit on", timeout=30_000)                       # inputs read live: the door is closed
    page.take_control()
    lamp.click()
    page.expect(lamp).to_have_class("bit on", timeout=30_000)
    with Robot(cell_server.target, "test-reader") as robot:
        assert robot.get_digital_io(2, "output").bits_on & (1 << 3)
    lamp.click()
    page.expect(lamp).to_have_class("bit", timeout=30_000)
    page.close()


def test_a_persons_commands_reach_the_device_with_their_token_and_are_recorded_as_theirs(
        chromium, keys, people, tmp_path):
    """The device uses tokens; the supervisor's own is a viewer's (its feeds). Olga, an
    operator, takes control from the page: her own token goes with each call, the device's
    audit names her, and the lock holder is her."""
    audit = tmp_path / "audit.log"
    secured = start_server(lockstep_pace=1.0, security=SecurityConfig(
        tls_cert=str(keys.certs.server_cert), tls_key=str(keys.certs.server_key),
        tokens=str(people.folder), audit_log=str(audit)))
    running = DashboardThread({"arm1": secured.target}, people, tls=keys.tls(),
                              token=people.token("supervisor"))
    try:
        page = Page(chromium, running, name="olga")
        page.take_control()
        page.shows("st-lock", "olga")
        page.close()
        wait_until(lambda: audit.exists() and "Activate" in audit.read_text(), timeout=10)
        records = [json.loads(line) for line in audit.read_text().splitlines()]
        made = {r["rpc"].rpartition("/")[2]: (r["who"], r["role"]) for r in records}
        for rpc in ("Connect", "Lock", "Activate"):
            assert made[rpc] == ("olga", "operator"), (rpc, made)
    finally:
        running.stop()
        secured.stop(grace=None)
