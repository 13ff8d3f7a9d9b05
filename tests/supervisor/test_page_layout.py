"""Issue 28 item 4, in Debian's headless Chromium on the real backend and real device servers:
the page is usable without horizontal scrolling at 1440x900, 1024x768 (a tablet on the cell's
fence) and 390x844 (a phone), for a cell of one arm and of two: nothing covers the 3D view,
the plots and the log keep a readable size. The 3D view draws at the device's pixel ratio as
far as the GPU's limits allow, and says when it draws at less (a software rasterizer).
Screenshots go to var/screenshots (not in git)."""
from __future__ import annotations

from dashboard_support import Page

SIZES = {"desktop": (1440, 900), "tablet": (1024, 768), "phone": (390, 844)}

# What is laid out where, read from the page: overflow, the views' and panels' boxes, the
# element drawn at each view's centre, the plots' and the log's sizes.
MEASURE = """() => {
    const box = (e) => { const r = e.getBoundingClientRect(); return {x: r.x, y: r.y + scrollY, w: r.width, h: r.height}; };
    const wide = [...document.querySelectorAll('body *')].filter((e) => {
        if (!e.getClientRects().length) return false;
        const r = e.getBoundingClientRect();
        return r.right > innerWidth + 0.5 && !e.closest('.log, .alarms, .panels, dialog');
    }).map((e) => e.id || e.className || e.tagName);
    // (.scene-wrap: the older page's single view, for LANDSCAPE_PAGE_DIST)
    const views = [...document.querySelectorAll('.cell-view, .scene-wrap')].filter((v) => v.getClientRects().length);
    return {
        scrollWidth: document.scrollingElement.scrollWidth, width: innerWidth, wide,
        views: views.map((v) => {
            const r = v.getBoundingClientRect();
            scrollTo(0, scrollY + r.top - 200);
            const s = v.getBoundingClientRect();
            const hit = document.elementFromPoint(s.x + s.width / 2, s.y + s.height / 2);
            return {device: v.dataset.device || 'arm1', box: box(v), centre: hit && hit.tagName};
        }),
        panels: box(document.querySelector('.panels')),
        plots: [...document.querySelectorAll('.plots figure')].map((f) => box(f.querySelector('canvas') || f)),
        log: box(document.getElementById('log')),
    };
}"""


def _overlap(a: dict, b: dict) -> bool:
    return not (a["x"] + a["w"] <= b["x"] or b["x"] + b["w"] <= a["x"]
                or a["y"] + a["h"] <= b["y"] or b["y"] + b["h"] <= a["y"])


def _check_layouts(page: Page, devices: list[str], name: str) -> None:
    for size, (width, height) in SIZES.items():
        page.page.set_viewport_size({"width": width, "height": height})
        page.page.wait_for_timeout(300)
        m = page.page.evaluate(MEASURE)
        assert m["scrollWidth"] <= m["width"], (size, m["scrollWidth"])
        assert m["wide"] == [], (size, m["wide"])
        shown = [v["device"] for v in m["views"]]
        assert shown == (devices if size != "phone" else [devices[0]]), (size, shown)
        for view in m["views"]:
            assert view["centre"] == "CANVAS", (size, view)          # nothing drawn over it
            assert not _overlap(view["box"], m["panels"]), (size, view)
            assert view["box"]["w"] >= min(300, width - 30) and view["box"]["h"] >= 250, (size, view)
        for plot in m["plots"]:
            assert plot["w"] >= 250 and plot["h"] >= 100, (size, plot)
        assert m["log"]["w"] >= 300 and m["log"]["h"] >= 150, (size, m["log"])
        page.page.evaluate("() => scrollTo(0, 0)")
        page.screenshot(f"layout-{name}-{size}")


def test_layouts_one_arm(chromium, dashboard):
    page = Page(chromium, dashboard)
    _check_layouts(page, ["arm1"], "one-arm")
    page.close()


def test_layouts_two_arms(chromium, two_arm_dashboard):
    page = Page(chromium, two_arm_dashboard)
    _check_layouts(page, ["arm1", "arm2"], "two-arms")
    # On a phone the chosen arm's view is shown: choose the other in the status bar.
    page.page.locator(".status-row[data-device='arm2'] .arm-name").click()
    page.expect(page.page.locator(".cell-view[data-device='arm2']")).to_be_visible()
    page.expect(page.page.locator(".cell-view[data-device='arm1']")).to_be_hidden()
    page.shows("panels-device", "arm2")
    page.close()


def _drawing(page: Page) -> dict:
    return page.page.evaluate("""() => {
        const canvas = document.querySelector('.cell-view[data-device="arm1"] canvas');
        const gl = window.cellViews.arm1.renderer.getContext();
        return {buffer: canvas.width, css: canvas.clientWidth, ratio: devicePixelRatio,
                largest: Math.min(gl.getParameter(gl.MAX_RENDERBUFFER_SIZE), ...gl.getParameter(gl.MAX_VIEWPORT_DIMS)),
                note: document.querySelector('.cell-view[data-device="arm1"] .scene-note').textContent};
    }""")


def test_the_3d_view_draws_at_the_devices_pixel_ratio_as_far_as_the_gpu_allows(chromium, dashboard):
    # ?render=full: as with a GPU (this machine has none: Chromium draws with SwiftShader).
    for ratio, width in ((2, 1440), (3, 4200)):
        page = Page(chromium, dashboard, query="?render=full", scale=ratio)
        page.page.set_viewport_size({"width": width, "height": 900})
        page.page.wait_for_timeout(500)
        d = _drawing(page)
        assert d["ratio"] == ratio
        expected = min(d["css"] * ratio, d["largest"])   # 4200 px at 3x is past the GPU's limit
        assert abs(d["buffer"] - expected) <= 2, d
        page.close()
    # Without a GPU, fewer pixels, and the page says so.
    page = Page(chromium, dashboard, scale=2)
    d = _drawing(page)
    assert d["buffer"] < d["css"] * 2
    assert "software" in d["note"]
    page.close()
