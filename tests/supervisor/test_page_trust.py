"""Who may drive the robot through the page, in Debian's headless Chromium on the real backend
and a real device server: a page served from another origin cannot (issue 25 item 1), a
signed-in viewer watches and may stop the cell but not command, and what the page shows of
who is signed in. Screenshots go to var/screenshots (not in git)."""
from __future__ import annotations

import http.server
import threading

import pytest

from dashboard_support import Page
from landscape.server.device.states import State

# The page another site serves: with the operator's cookie in the same browser, it tries the
# supervisor's WebSocket (session, lock, power, a move), fetch POSTs and a form POST.
EVIL_PAGE = """<!doctype html><html><body>
<iframe name="sink"></iframe>
<form id="form" method="POST" action="{target}api/sign-out" target="sink">
  <input name="token" value="x"></form>
<script>
const target = "{target}";
const results = window.results = {{}};
function drive() {{
  return new Promise((resolve) => {{
    const ws = new WebSocket(target.replace('http', 'ws') + 'ws');
    ws.onopen = () => {{
      let id = 0;
      const send = (rpc, request) => ws.send(JSON.stringify({{ device: 'arm1', rpc, id: ++id, request }}));
      send('landscape.v1.SessionService/Connect', {{ hello: {{ clientName: 'evil' }} }});
      setTimeout(() => send('landscape.v1.DeviceService/Lock', {{}}), 300);
      setTimeout(() => send('landscape.v1.DeviceService/Activate', {{}}), 600);
      setTimeout(() => send('landscape.v1.DeviceService/MoveAbsolute',
        {{ frame: 'REFERENCE_FRAME_JOINT_FRAME', values: [0.6, 0.2, 1.4, 0, 1.4, 0] }}), 1500);
      setTimeout(() => resolve('open'), 4000);
    }};
    ws.onclose = (event) => resolve(`closed ${{event.code}}`);
  }});
}}
async function post(path, options) {{
  try {{
    const reply = await fetch(target + path, {{ method: 'POST', credentials: 'include', ...options }});
    return `answered ${{reply.status}} ${{reply.type}}`;
  }} catch (error) {{
    return `blocked: ${{error}}`;
  }}
}}
(async () => {{
  results.ws = await drive();
  const body = JSON.stringify({{ token: 'x' }});
  results.simple = await post('api/sign-out', {{ mode: 'no-cors', headers: {{ 'Content-Type': 'text/plain' }}, body }});
  results.preflighted = await post('api/sign-out', {{ headers: {{ 'X-Landscape-Request': 'page' }} }});
  results.readDevices = await fetch(target + 'api/devices', {{ credentials: 'include' }})
    .then((reply) => `read ${{reply.status}}`, (error) => `blocked: ${{error}}`);
  document.getElementById('form').submit();
  results.done = true;
}})();
</script></body></html>"""


class _EvilSite:
    """A tiny HTTP server on another local port: another origin, the same site."""

    def __init__(self, target: str):
        page = EVIL_PAGE.format(target=target).encode()

        class Handler(http.server.BaseHTTPRequestHandler):
            def do_GET(self):
                self.send_response(200)
                self.send_header("Content-Type", "text/html")
                self.end_headers()
                self.wfile.write(page)

            def log_message(self, *args):
                pass

        self.server = http.server.ThreadingHTTPServer(("127.0.0.1", 0), Handler)
        self.url = f"http://127.0.0.1:{self.server.server_address[1]}/"
        threading.Thread(target=self.server.serve_forever, daemon=True).start()

    def close(self):
        self.server.shutdown()
        self.server.server_close()


@pytest.fixture
def evil_site(dashboard):
    site = _EvilSite(dashboard.url)
    yield site
    site.close()


def test_a_page_from_another_origin_cannot_drive_the_robot(chromium, dashboard, cell_server,
                                                          evil_site):
    """Olga is signed in in this browser; a page from another port of the same host (the
    same site: her SameSite cookie goes along) tries the WebSocket, fetch POSTs and a form
    POST. All refused: nothing moves, the lock is not taken, and she is still signed in."""
    olga = Page(chromium, dashboard, name="olga")
    before = cell_server.device.feedback().position.copy()
    evil = olga.context.new_page()
    evil.goto(evil_site.url)
    evil.wait_for_function("window.results && window.results.done === true", timeout=30_000)
    results = evil.evaluate("window.results")
    assert results["ws"].startswith("closed"), results    # refused before the upgrade
    assert results["simple"] == "answered 0 opaque", results   # sent blind, and refused
    assert results["preflighted"].startswith("blocked"), results
    assert results["readDevices"].startswith("blocked"), results
    evil.wait_for_timeout(500)   # the form's POST reaches the supervisor (and is refused)
    assert cell_server.device.state is State.UNLOCKED
    assert not cell_server.device.status().locked
    assert cell_server.device.feedback().position == pytest.approx(before, abs=1e-4)
    me = olga.page.evaluate("fetch('/api/me').then((reply) => reply.status)")
    assert me == 200   # the cross-site sign-outs did nothing
    olga.shows("connection", "connected")
    olga.take_control()   # and she commands as before
    evil.close()
    olga.close()


def test_a_viewer_watches_with_the_controls_disabled_and_may_stop_the_cell(chromium, dashboard,
                                                                          cell_server):
    vera = Page(chromium, dashboard, name="vera")
    vera.shows("person", "vera (viewer)")
    vera.shows("role", "watching only (viewer)")
    assert "commanding needs the operator role" in vera.page.locator("#role").get_attribute("title")
    for button in ("btn-session", "btn-lock", "btn-activate", "btn-speed", "btn-estop-release",
                   "btn-reset", "btn-path-run"):
        locator = vera.page.locator(f"#{button}")
        assert locator.is_disabled(), button
        assert "you are signed in as viewer" in locator.get_attribute("title"), button
    assert vera.page.locator("#estop-arm1").is_enabled()
    # A frame forged in her own page (her cookie, her origin): refused with the reason.
    status = vera.page.evaluate("""() => new Promise((resolve) => {
        const ws = new WebSocket(`ws://${location.host}/ws`);
        ws.onopen = () => ws.send(JSON.stringify({device: 'arm1', id: 1, request: {},
                                                  rpc: 'landscape.v1.DeviceService/Lock'}));
        ws.onmessage = (event) => {
          const frame = JSON.parse(event.data);
          if (frame.id === 1) { ws.close(); resolve(frame.status); }
        };
      })""")
    assert status["code"] == 7 and "Lock needs the operator role" in status["message"], status
    assert not cell_server.device.status().locked
    vera.screenshot("viewer")
    vera.click("estop-arm1")   # anyone watching the cell may stop it
    vera.shows("st-estop", "PRESSED")
    vera.shows("st-state", "error")
    vera.close()


def test_the_page_says_who_is_signed_in_and_signing_out_shows_the_form(chromium, dashboard):
    olga = Page(chromium, dashboard, name="olga")
    olga.shows("person", "olga (operator)")
    assert olga.page.locator("#btn-reset").is_disabled()   # Reset is an admin's
    olga.click("btn-sign-out")
    olga.expect(olga.page.locator("#sign-in")).to_be_visible()
    assert olga.page.evaluate("fetch('/api/me').then((reply) => reply.status)") == 401
    olga.page.fill("#sign-in-token", "not-a-token-of-this-cell-0123456789")
    olga.page.click("#btn-sign-in")
    olga.shows("sign-in-error", "Not signed in")
    olga.close()
