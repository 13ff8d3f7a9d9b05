"""Issue 28 item 6, in Debian's headless Chromium on the real backend and real device servers:
the e-stop and the controls work from the keyboard, and axe-core (installed by `make install`
into the page's devDependencies) run inside the page finds no serious or critical violation,
on the sign-in form, the page of one arm and of two, at a desk and on a phone, with its
panels open, a refusal, a banner and the device's question shown."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dashboard_support import Page
from landscape.server.device.states import State
from support import wait_until

AXE = Path(__file__).resolve().parents[2] / "supervisor_gui_web" / "frontend" / "node_modules" / "axe-core" / "axe.min.js"
RUN_AXE = """async () => {
    const result = await axe.run(document, { resultTypes: ['violations'] });
    return result.violations.filter((v) => ['serious', 'critical'].includes(v.impact))
        .map((v) => ({ id: v.id, impact: v.impact,
            nodes: v.nodes.slice(0, 3).map((n) => `${n.target.join(' ')}: ${n.failureSummary}`) }));
}"""


@pytest.fixture(scope="module")
def axe_source():
    if not AXE.is_file():
        pytest.skip(f"{AXE} is missing: `make install` installs the page's npm packages")
    return AXE


def _violations(page: Page, axe_source: Path) -> list:
    if not page.page.evaluate("() => typeof window.axe === 'object'"):
        page.page.add_script_tag(path=str(axe_source))
    return page.page.evaluate(RUN_AXE)


def _open_everything(page: Page) -> None:
    page.page.evaluate("() => document.querySelectorAll('details').forEach((d) => { d.open = true; })")


def test_axe_finds_nothing_serious_on_the_sign_in_form(chromium, dashboard, axe_source):
    context = chromium.new_context()
    tab = context.new_page()
    tab.goto(dashboard.url)
    tab.wait_for_selector("#sign-in:not([hidden])")
    tab.add_script_tag(path=str(axe_source))
    assert tab.evaluate(RUN_AXE) == []
    context.close()


def test_axe_finds_nothing_serious_on_the_page_in_use(chromium, dashboard, cell_server, axe_source):
    page = Page(chromium, dashboard)
    _open_everything(page)
    assert _violations(page, axe_source) == []
    page.take_control()
    page.click("btn-io-list")
    page.page.fill("#path-points", "p1 0.6 0.2 1.4 0 1.4 0")
    page.click("btn-path-load")
    page.click("btn-release")                      # refused: the refusal shown
    page.expect(page.page.locator("#refusal")).to_be_visible()
    page.page.fill("#move-v0", "0.3")                # the move form's preview note
    assert _violations(page, axe_source) == []
    page.click("estop-arm1")                         # alarms listed, then the device's question
    page.click("btn-estop-release")
    page.expect(page.page.locator("#rsvp")).to_be_visible(timeout=30_000)
    assert _violations(page, axe_source) == []
    page.page.keyboard.press("Escape")
    page.page.set_viewport_size({"width": 390, "height": 844})
    assert _violations(page, axe_source) == []
    page.close()


def test_axe_finds_nothing_serious_with_two_arms(chromium, two_arm_dashboard, axe_source):
    owner = Page(chromium, two_arm_dashboard)
    asker = Page(chromium, two_arm_dashboard, name="operator-1")
    owner.take_control()
    asker.click("btn-request-control")               # the owner's hand-over banner
    owner.expect(owner.page.get_by_test_id("handover-arm1")).to_be_visible()
    _open_everything(owner)
    assert _violations(owner, axe_source) == []
    assert _violations(asker, axe_source) == []
    asker.close()
    owner.close()


def _tab_to(page: Page, element_id: str, most: int = 40) -> None:
    """Tab from where the page's focus is until `element_id` has it."""
    for _ in range(most):
        page.page.keyboard.press("Tab")
        if page.page.evaluate("() => document.activeElement && document.activeElement.id") == element_id:
            return
    raise AssertionError(f"#{element_id} not reached in {most} Tabs")


def test_the_estop_and_the_controls_work_from_the_keyboard(chromium, dashboard, cell_server):
    page = Page(chromium, dashboard)
    for button in ("btn-session", "btn-lock", "btn-activate"):
        page.expect(page.page.locator(f"#{button}")).to_be_enabled()
        page.page.focus(f"#{button}")
        page.page.keyboard.press("Enter")
    page.shows("st-state", "resting")
    page.page.focus("#manual-control")
    page.page.keyboard.press("Space")
    page.shows("st-manual", "teach pendant")
    # A jog button held with Space moves the arm; letting go stops it.
    before = np.array(cell_server.device.feedback().position)
    page.page.focus("[data-testid='jog-J1+']")
    page.page.keyboard.down(" ")
    page.page.wait_for_timeout(700)
    page.page.keyboard.up(" ")
    wait_until(lambda: cell_server.device.state is State.RESTING, timeout=10)
    assert cell_server.device.feedback().position[0] > before[0] + 0.005
    # On a page just opened (a viewer's), the e-stop is a few Tabs away, and Enter presses it.
    vera = Page(chromium, dashboard, name="vera")
    _tab_to(vera, "estop-arm1", most=12)
    vera.page.keyboard.press("Enter")
    vera.expect(vera.status("estop")).to_have_text("e-stop PRESSED")
    wait_until(lambda: cell_server.device.state is State.ERROR, timeout=10)
    vera.close()
    page.close()
