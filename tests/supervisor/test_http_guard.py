"""What the supervisor accepts over HTTP and its WebSocket, without a browser: its own origin
only (and the allow-list), signed-in people only, state-changing requests safe against other
sites, half-sent requests dropped, strangers' connections bounded; and what each call to a
device carries. A real device server, the real backend, raw sockets and aiohttp clients."""
from __future__ import annotations

import asyncio
import json
import socket

import aiohttp
import grpc
import pytest

from dashboard_support import (CONNECT, DEVICE, PageClient, open_page, origin_of, page_headers,
                               run_with_page, signed_in_http)
from landscape.server.device.states import State
from landscape.supervisor import DashboardConfig, DeviceTarget, start
from landscape.supervisor.connections import HEADER_TIMEOUT_S
from support import wait_until

EVIL = "http://evil.example"


def run_with_dashboard(server, body, people, **config):
    """body(dashboard) against a backend on a free port, within a time limit."""
    async def main():
        dashboard = await start(DashboardConfig(
            devices=(DeviceTarget("arm1", server.target),), port=0,
            sign_in_tokens=str(people.folder), **config))
        try:
            await body(dashboard)
        finally:
            await dashboard.stop()
    asyncio.run(asyncio.wait_for(main(), 120))


async def handshake_status(http: aiohttp.ClientSession, url: str, origin: str | None) -> int:
    """The status a WebSocket handshake to `url` gets (101 when it was upgraded)."""
    try:
        async with http.ws_connect(url + "ws", origin=origin):
            return 101
    except aiohttp.WSServerHandshakeError as refused:
        return refused.status


def test_a_websocket_from_another_origin_is_refused_before_the_upgrade(server, people):
    """Issue 25 item 1: a client sending Origin: http://evil.example ran PathMove. Refused
    with 403 before any frame, with olga's valid sign-in cookie, and without; the same for
    a page on another port of the same host, and for no Origin at all."""
    async def body(dashboard):
        other_port = origin_of(dashboard.url).rsplit(":", 1)[0] + ":9"
        async with await signed_in_http(dashboard.url, people.token("olga")) as http:
            for origin in (EVIL, other_port, "null", None):
                assert await handshake_status(http, dashboard.url, origin) == 403, origin
            assert await handshake_status(http, dashboard.url, origin_of(dashboard.url)) == 101
        async with aiohttp.ClientSession() as stranger:
            assert await handshake_status(stranger, dashboard.url, EVIL) == 403
    before = server.device.feedback().position.copy()
    run_with_dashboard(server, body, people)
    assert server.device.state is State.UNLOCKED and not server.device.status().locked
    assert server.device.feedback().position == pytest.approx(before, abs=1e-4)   # nothing moved


def test_the_loopback_names_of_its_port_are_its_own_origin(server, people):
    async def body(dashboard):
        port = dashboard.url.rstrip("/").rsplit(":", 1)[1]
        async with await signed_in_http(dashboard.url, people.token("vera")) as http:
            for name in ("localhost", "127.0.0.1", "[::1]"):
                status = await handshake_status(http, dashboard.url, f"http://{name}:{port}")
                assert status == 101, name
    run_with_dashboard(server, body, people)


def test_an_allowed_origin_is_let_in(server, people):
    async def body(dashboard):
        async with await signed_in_http(dashboard.url, people.token("vera")) as http:
            assert await handshake_status(http, dashboard.url, "https://panel.example") == 101
            assert await handshake_status(http, dashboard.url, EVIL) == 403
    run_with_dashboard(server, body, people, allowed_origins=("https://panel.example:443",))


def test_without_a_sign_in_only_the_page_itself_is_served(server, people):
    async def body(dashboard):
        url = dashboard.url
        async with aiohttp.ClientSession() as http:
            async with http.get(url) as reply:
                assert reply.status == 200 and "sign-in-form" in await reply.text()
            for path in ("api/devices", "api/me"):
                async with http.get(url + path) as reply:
                    assert reply.status == 401, path
            assert await handshake_status(http, url, origin_of(url)) == 401
            async with http.post(url + "api/sign-out", headers=page_headers(url)) as reply:
                assert reply.status == 401
    run_with_dashboard(server, body, people)


@pytest.mark.parametrize("body, content_type, status", [
    ({"token": "not-a-token-of-this-folder-0123456789"}, "application/json", 401),
    ({"token": ""}, "application/json", 400),
    ({"nothing": 1}, "application/json", 400),
    ("token=x", "application/x-www-form-urlencoded", 415),
])
def test_a_sign_in_that_cannot_be_is_refused_and_sets_no_cookie(server, people, body,
                                                                 content_type, status):
    async def run(dashboard):
        url = dashboard.url
        data = json.dumps(body) if isinstance(body, dict) else body
        async with aiohttp.ClientSession(cookie_jar=aiohttp.CookieJar(unsafe=True)) as http:
            async with http.post(url + "api/sign-in", data=data, headers={
                    **page_headers(url), "Content-Type": content_type}) as reply:
                assert reply.status == status, await reply.text()
                assert "landscape_sign_in" not in reply.cookies
                if status == 401:
                    assert "token" in (await reply.json())["error"]
    run_with_dashboard(server, run, people)


def test_state_changing_requests_need_the_pages_origin_and_header(server, people):
    """A cross-site form or fetch can set neither: the sign-in and the sign-out are refused
    without them, even with a valid cookie (SameSite does not part two ports of one host)."""
    async def body(dashboard):
        url = dashboard.url
        token = {"token": people.token("olga")}
        async with await signed_in_http(url, people.token("olga")) as http:
            for headers in ({}, {"Origin": EVIL, "X-Landscape-Request": "page"},
                            {"Origin": origin_of(url)}, {"Origin": "null"}):
                for path, data in (("api/sign-in", token), ("api/sign-out", None)):
                    async with http.post(url + path, json=data, headers=headers) as reply:
                        assert reply.status == 403, (path, headers)
            async with http.get(url + "api/me") as reply:   # still signed in
                assert (await reply.json())["name"] == "olga"
            async with http.options(url + "api/sign-in", headers={
                    "Origin": EVIL, "Access-Control-Request-Method": "POST"}) as reply:
                assert reply.status == 403 and "Access-Control-Allow-Origin" not in reply.headers
    run_with_dashboard(server, body, people)


def test_a_viewer_watches_and_may_stop_but_every_command_is_refused(server, people):
    """Vera's forged frames: a session, the lock, Activate, an output, the e-stop's release:
    PERMISSION_DENIED with the reason, and nothing reaches the device; the e-stop press is
    allowed to every role."""
    async def body(page, dashboard):
        forged = [(CONNECT, {"hello": {"clientName": "vera"}}), (DEVICE + "Lock", None),
                  (DEVICE + "Activate", None), (DEVICE + "Release", None),
                  ("landscape.v1.DigitalIOService/SetDigitalIO",
                   {"type": "output", "unitId": 2, "bitsOn": 8}),
                  (DEVICE + "OperatePanel", {"action": "PANEL_ACTION_RELEASE_ESTOP"}),
                  (DEVICE + "Reset", None)]
        for rpc, request in forged:
            status = (await page.call(rpc, request))["status"]
            assert status["code"] == grpc.StatusCode.PERMISSION_DENIED.value[0], rpc
            assert "you are signed in as viewer" in status["message"], status
        assert server.device.state is State.UNLOCKED and not server.device.status().locked
        description = await page.call(DEVICE + "GetRobotDescription")
        assert "reply" in description   # reading is a viewer's
        pressed = await page.call(DEVICE + "OperatePanel",
                                  {"action": "PANEL_ACTION_PRESS_ESTOP"})
        assert pressed["reply"]["estopPressed"] is True
    run_with_page(server, body, people, person="vera")
    assert server.device.state is State.ERROR   # stopped, as anyone watching may


def test_an_operator_commands_but_neither_resets_nor_works_the_door(server, people):
    async def body(page, dashboard):
        await page.call(CONNECT, {"hello": {}})
        assert "reply" in await page.call(DEVICE + "Lock")
        for rpc, request in ((DEVICE + "Reset", None), (DEVICE + "OperatePanel",
                                                        {"action": "PANEL_ACTION_OPEN_DOOR"})):
            status = (await page.call(rpc, request))["status"]
            assert status["code"] == grpc.StatusCode.PERMISSION_DENIED.value[0], rpc
            assert "needs the admin role" in status["message"]
        assert server.device.status().lock_holder == "olga"
    run_with_page(server, body, people)


def test_signing_out_closes_the_persons_pages_and_their_lock_is_released(server, people):
    async def body(page, dashboard):
        await page.call(CONNECT, {"hello": {}})
        await page.call(DEVICE + "Lock")
        await page.call(DEVICE + "Activate")
        async with page.http.post(dashboard.url + "api/sign-out",
                                  headers=page_headers(dashboard.url)) as reply:
            assert reply.status == 204
        closed = await asyncio.wait_for(page.ws.receive(), 30)
        while closed.type is aiohttp.WSMsgType.TEXT:
            closed = await asyncio.wait_for(page.ws.receive(), 30)
        assert page.ws.close_code == 4001 and "signed out" in (closed.extra or "")
        async with page.http.get(dashboard.url + "api/me") as reply:
            assert reply.status == 401
    run_with_page(server, body, people)
    wait_until(lambda: server.device.state is State.UNLOCKED, timeout=20)


def _half_sent_request(url: str) -> socket.socket:
    host, port = url.split("//")[1].rstrip("/").rsplit(":", 1)
    sock = socket.create_connection((host, int(port)), timeout=10)
    sock.sendall(b"GET /api/devices HT")   # half a request line, and then nothing
    return sock


def _closed_by_the_server(sock: socket.socket, within: float) -> bool:
    sock.settimeout(within)
    try:
        return sock.recv(1024) == b""
    except ConnectionResetError:
        return True
    except TimeoutError:
        return False


def test_a_request_whose_head_does_not_arrive_is_dropped(server, people):
    """Issue 25 item 1: 3,000 half-sent requests were held 60 s. A connection that sends half
    a request line and waits is closed by the server (in HEADER_TIMEOUT_S; the test gives it
    four times that, and asserts the close, not its time)."""
    async def body(dashboard):
        sock = await asyncio.to_thread(_half_sent_request, dashboard.url)
        with sock:
            assert await asyncio.to_thread(_closed_by_the_server, sock, 4 * HEADER_TIMEOUT_S)
    run_with_dashboard(server, body, people)


def test_connections_that_show_no_sign_in_are_bounded_and_signed_in_pages_stay(server, people):
    async def body(dashboard):
        http, ws = await open_page(dashboard.url, people.token("olga"))   # signed in first
        async with http, ws:
            held = [await asyncio.to_thread(_half_sent_request, dashboard.url) for _ in range(3)]
            try:
                one_more = await asyncio.to_thread(_half_sent_request, dashboard.url)
                with one_more:   # over the limit: closed at once, long before the head timeout
                    assert await asyncio.to_thread(_closed_by_the_server, one_more,
                                                   HEADER_TIMEOUT_S / 2)
                page = PageClient(ws)   # the signed-in page works on
                assert "reply" in await page.call(DEVICE + "GetRobotDescription")
            finally:
                for sock in held:
                    sock.close()
    run_with_dashboard(server, body, people, max_unauthenticated=3)


class _Recorder(grpc.GenericRpcHandler):
    """A stand-in device at the network's edge: it records each call's method and metadata
    and answers UNIMPLEMENTED."""

    def __init__(self):
        self.calls: list[tuple[str, dict]] = []

    def service(self, handler_call_details):
        self.calls.append((handler_call_details.method,
                           dict(handler_call_details.invocation_metadata)))
        return None


@pytest.mark.parametrize("forward", [True, False], ids=["devices-with-tokens", "loopback"])
def test_every_call_says_whom_it_is_for_and_carries_the_right_token(people, forward):
    """identity.md: landscape-client and landscape-on-behalf-of on every call; where the
    devices use tokens, the person's own token on theirs and the supervisor's on the feeds."""
    recorder = _Recorder()
    supervisor_token = people.token("supervisor") if forward else None

    async def main():
        device = grpc.aio.server(handlers=[recorder])
        port = device.add_insecure_port("127.0.0.1:0")
        await device.start()
        dashboard = await start(DashboardConfig(
            devices=(DeviceTarget("arm1", f"127.0.0.1:{port}"),), port=0,
            sign_in_tokens=str(people.folder), token=supervisor_token))
        try:
            http, ws = await open_page(dashboard.url, people.token("olga"))
            async with http, ws:
                await PageClient(ws).call(DEVICE + "GetRobotDescription")
            async with asyncio.timeout(30):   # the feeds have called too
                while not any(m.endswith("/StreamState") for m, _ in recorder.calls):
                    await asyncio.sleep(0.01)
        finally:
            await dashboard.stop()
            await device.stop(None)
    asyncio.run(asyncio.wait_for(main(), 60))

    mine = [md for method, md in recorder.calls if method.endswith("/GetRobotDescription")]
    feeds = [md for method, md in recorder.calls if method.endswith("/StreamState")]
    assert mine and feeds
    assert mine[0]["landscape-client"] == feeds[0]["landscape-client"] == "supervisor"
    assert mine[0]["landscape-on-behalf-of"] == "olga"
    assert feeds[0]["landscape-on-behalf-of"] == "every browser"
    if forward:
        assert mine[0]["authorization"] == f"Bearer {people.token('olga')}"
        assert feeds[0]["authorization"] == f"Bearer {supervisor_token}"
    else:
        assert "authorization" not in mine[0] and "authorization" not in feeds[0]
