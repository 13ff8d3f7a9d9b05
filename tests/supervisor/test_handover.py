"""Issue 28 item 2: control asked for and handed over between two operators signed in to the
same supervisor (supervisor_gui_web/handover.py), in Debian's headless Chromium on the real
backend and real device servers (the desk's refusals: test_control_desk.py).
The holder declines or hands over; handing over powers down and releases, and the asker's
session then holds the lock; nothing takes a lock without its holder's word."""
from __future__ import annotations

from dashboard_support import Page
from landscape.server.device.states import State
from support import wait_until

def _banner(page: Page, device: str = "arm1"):
    return page.page.get_by_test_id(f"handover-{device}")


def test_the_holder_declines_then_hands_over(chromium, dashboard, cell_server):
    olga = Page(chromium, dashboard)
    other = Page(chromium, dashboard, name="operator-1")
    olga.take_control()
    other.expect(other.page.locator("#btn-request-control")).to_be_visible()
    other.click("btn-request-control")
    other.shows("handover-status", "asked olga for control; waiting for an answer")
    olga.expect(_banner(olga)).to_contain_text("operator-1 asks for control of arm1")
    olga.screenshot("handover-asked")
    olga.page.get_by_test_id("decline-arm1").click()
    other.shows("handover-status", "olga declined to hand arm1 over")
    olga.expect(_banner(olga)).to_be_hidden()
    assert cell_server.device.status().lock_holder == "olga"
    # Asked again: handed over. The arm powers down; the asker holds the lock.
    other.click("btn-request-control")
    olga.page.get_by_test_id("hand-over-arm1").click()
    other.expect(other.status("lock")).to_have_text("lock: operator-1 (you)", timeout=30_000)
    other.shows("handover-status", "olga handed arm1 over")
    olga.expect(olga.status("lock")).to_have_text("lock: operator-1")
    olga.expect(olga.page.get_by_test_id("lost-arm1")).to_be_hidden()   # given, not lost
    assert cell_server.device.status().lock_holder == "operator-1"
    assert cell_server.device.state is State.INACTIVE
    other.click("btn-activate")
    other.shows("st-state", "resting")
    assert olga.page.locator("#btn-activate").is_disabled()
    other.close()
    olga.close()


def test_a_motion_in_progress_is_not_handed_over(chromium, dashboard, cell_server):
    olga = Page(chromium, dashboard)
    other = Page(chromium, dashboard, name="operator-1")
    olga.take_control()
    olga.page.fill("#path-name", "far")
    # Ten points back and forth, five times the two it had: the motion still runs when the
    # stop comes on a busy machine (the two ended first on the suite's two workers).
    olga.page.fill("#path-points", "\n".join(
        f"f{i} 1.2 0.4 1.2 0 1.3 0" if i % 2 else f"f{i} -1.2 0.1 1.5 0 1.4 0.8"
        for i in range(1, 11)))
    olga.click("btn-path-load")
    olga.click("btn-path-run")
    olga.shows("st-state", "moving")
    other.click("btn-request-control")
    olga.page.get_by_test_id("hand-over-arm1").click()
    olga.shows("refusal-text", "stop and abort the motion before handing the lock over")
    assert cell_server.device.status().lock_holder == "olga"
    olga.click("btn-stop")
    olga.shows("st-state", "paused")
    olga.click("btn-abort")
    olga.shows("st-state", "resting")
    olga.page.get_by_test_id("hand-over-arm1").click()
    other.expect(other.status("lock")).to_have_text("lock: operator-1 (you)", timeout=30_000)
    other.close()
    olga.close()


def test_one_arm_of_two_is_handed_over(chromium, two_arm_dashboard, two_arm_servers):
    first, second = two_arm_servers
    olga = Page(chromium, two_arm_dashboard)
    other = Page(chromium, two_arm_dashboard, name="operator-1")
    for device in ("arm1", "arm2"):
        olga.page.locator(f".status-row[data-device='{device}'] .arm-name").click()
        olga.take_control()
    other.page.locator(".status-row[data-device='arm2'] .arm-name").click()
    other.click("btn-request-control")
    olga.page.get_by_test_id("hand-over-arm2").click()
    other.expect(other.status("lock", "arm2")).to_have_text("lock: operator-1 (you)", timeout=30_000)
    olga.expect(olga.status("lock", "arm1")).to_have_text("lock: olga (you)")
    assert (first.device.status().lock_holder, second.device.status().lock_holder) == ("olga", "operator-1")
    other.close()
    olga.close()
