"""The web supervisor's backend: aiohttp serving the built page, sign-in, the device list and
one WebSocket per browser (wire.py says what travels on it).

Every request passes http_guard.py first (origin, cross-site, sign-in); connections that
never show a sign-in are bounded in time and number (connections.py).

aiohttp, because one well-kept package gives the HTTP server, WebSockets and static files on
the asyncio loop that grpc.aio already runs on: no second server process, no ASGI layer.
"""
from __future__ import annotations

import asyncio
import contextlib
import json
import logging
import socket
from dataclasses import dataclass
from pathlib import Path

from aiohttp import WSMsgType, web

from landscape.server.security.auth import TokenStore
from landscape.supervisor import sign_in_routes
from landscape.supervisor.config import DashboardConfig
from landscape.supervisor.connections import HEADER_TIMEOUT_S, ConnectionGuard
from landscape.supervisor.console import Console
from landscape.supervisor.device_hub import DeviceHub
from landscape.supervisor.http_guard import GUARD, POLICY, SIGN_INS, WS_PATH, guard, signed_in
from landscape.supervisor.origins import OriginPolicy, own_origins
from landscape.supervisor.outbox import Outbox, TooSlow
from landscape.supervisor.sign_in import SignIn, SignIns
from landscape.supervisor.supervisor_calls import SupervisorCalls

log = logging.getLogger(__name__)

STATIC_DIR = Path(__file__).parent / "frontend" / "dist"
HUBS = web.AppKey("hubs", dict)
CALLS = web.AppKey("calls", SupervisorCalls)
CONFIG = web.AppKey("config", DashboardConfig)
# WebSocket close code 1013 "try again later": the page reconnects and is sent the history.
CLOSE_TOO_SLOW = 1013
# The person's sign-in ended (signed out, expired): the page shows the sign-in form and why.
CLOSE_SIGNED_OUT = 4001
SWEEP_PERIOD_S = 10.0   # how often expired sign-ins are ended (and their pages closed)


def create_app(config: DashboardConfig, origins: tuple[str, ...]) -> web.Application:
    """The app; `origins`: the supervisor's own (origins.own_origins of where it serves)."""
    static = Path(config.static_dir) if config.static_dir else STATIC_DIR
    if not (static / "index.html").is_file():
        raise FileNotFoundError(f"the page is not built: {static / 'index.html'} is missing "
                                "(`make install` builds it with npm)")
    app = web.Application(middlewares=[guard])
    app[CONFIG] = config
    app[POLICY] = OriginPolicy(origins, config.allowed_origins)
    app[SIGN_INS] = SignIns(TokenStore.load(config.sign_in_tokens),
                            forward_tokens=config.token is not None,
                            idle_s=config.sign_in_idle_s, max_age_s=config.sign_in_max_age_s)
    app[GUARD] = ConnectionGuard(config.max_unauthenticated)
    app[CALLS] = SupervisorCalls()
    app.router.add_get(WS_PATH, _websocket)
    app.router.add_get("/api/devices", _devices)
    sign_in_routes.add_routes(app)
    async def index(request: web.Request) -> web.FileResponse:
        return web.FileResponse(static / "index.html")

    app.router.add_get("/", index)
    app.router.add_static("/", static)
    app.cleanup_ctx.append(_device_hubs)
    app.cleanup_ctx.append(_sweeper)
    return app


async def _sweeper(app: web.Application):
    async def sweep():
        while True:
            await asyncio.sleep(SWEEP_PERIOD_S)
            app[SIGN_INS].sweep()
    task = asyncio.create_task(sweep())
    yield
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task


async def _device_hubs(app: web.Application):
    config = app[CONFIG]
    hubs = {d.name: DeviceHub(d, config.display_rate_hz, config.tls, config.token)
            for d in config.devices}
    for hub in hubs.values():
        await hub.start()
    app[HUBS] = hubs
    yield
    await asyncio.gather(*(hub.close() for hub in hubs.values()))


async def _devices(request: web.Request) -> web.Response:
    hubs = request.app[HUBS]
    return web.json_response([{"name": hub.name, "target": hub.target} for hub in hubs.values()])


async def _websocket(request: web.Request) -> web.WebSocketResponse:
    person = signed_in(request)   # the guard checked the Origin and the sign-in already
    ws = web.WebSocketResponse(heartbeat=10.0)
    await ws.prepare(request)
    hubs = request.app[HUBS]
    sign_ins = request.app[SIGN_INS]
    outbox = Outbox()
    calls = request.app[CALLS]
    console = Console(hubs, outbox, person, calls)
    sign_ins.page_opened(person)
    for hub in hubs.values():
        hub.join(outbox)
    sender = asyncio.create_task(_send(ws, outbox))
    reader = asyncio.create_task(_receive(ws, person, sign_ins, console))
    signed_out = asyncio.create_task(person.ended.wait())
    try:
        await asyncio.wait((reader, sender, signed_out), return_when=asyncio.FIRST_COMPLETED)
    finally:
        for task in (reader, signed_out):
            task.cancel()
        await asyncio.gather(reader, signed_out, return_exceptions=True)
        # Closed here, with no receive waiting, the close handshake completes and the browser
        # hears why (aiohttp drops the socket, 1006, when another task is receiving).
        if person.ended.is_set():
            await ws.close(code=CLOSE_SIGNED_OUT, message=person.why_ended.encode()[:120])
        elif sender.done() and sender.result() == CLOSE_TOO_SLOW:
            await ws.close(code=CLOSE_TOO_SLOW, message=b"too slow")
        sign_ins.page_closed(person)
        for hub in hubs.values():
            hub.leave(outbox)
        outbox.close()
        await console.close()   # ends this page's sessions: the device's disconnect handler runs
        await sender
    return ws


async def _receive(ws: web.WebSocketResponse, person: SignIn, sign_ins: SignIns,
                   console: Console) -> None:
    """The page's frames, each to the console, until the page closes its socket."""
    async for message in ws:
        if message.type is not WSMsgType.TEXT:
            continue
        try:
            body = json.loads(message.data)
        except json.JSONDecodeError:
            continue   # not a frame of ours; nothing to answer it with
        if isinstance(body, dict) and not person.ended.is_set():
            sign_ins.touch(person)
            console.receive(body)


async def _send(ws: web.WebSocketResponse, outbox: Outbox) -> int | None:
    """Frames to the page until its outbox closes; CLOSE_TOO_SLOW if it fell behind."""
    try:
        while batch := await outbox.take():
            for text in batch:
                await ws.send_str(text)
    except TooSlow as error:
        log.warning("closing a browser's connection: %s", error)
        return CLOSE_TOO_SLOW
    except ConnectionError:
        pass   # the browser went away; the receive loop ends too
    return None


@dataclass
class RunningDashboard:
    runner: web.AppRunner
    server: asyncio.base_events.Server
    url: str

    @property
    def sign_ins(self) -> SignIns:
        return self.runner.app[SIGN_INS]

    def devices_answering(self) -> dict[str, bool]:
        return {name: hub.answering for name, hub in self.runner.app[HUBS].items()}

    async def stop(self) -> None:
        self.server.close()
        await self.runner.cleanup()


async def start(config: DashboardConfig) -> RunningDashboard:
    """Serve on config.host:config.port (0 picks a free port); returns once listening."""
    listening = socket.create_server((config.host.strip("[]"), config.port),
                                     family=_family(config.host))
    host, port = listening.getsockname()[:2]
    app = create_app(config, own_origins(config.host, port))
    # keepalive_timeout is also how long a request's head may take to arrive (connections.py)
    runner = web.AppRunner(app, access_log=None, keepalive_timeout=HEADER_TIMEOUT_S)
    await runner.setup()
    server = await asyncio.get_running_loop().create_server(app[GUARD].serve(runner.server),
                                                            sock=listening)
    shown = f"[{host}]" if ":" in host else host
    return RunningDashboard(runner, server, f"http://{shown}:{port}/")


def _family(host: str) -> socket.AddressFamily:
    return socket.AF_INET6 if ":" in host else socket.AF_INET
