"""The web supervisor's backend: aiohttp serving the built page, the device list and one
WebSocket per browser (wire.py says what travels on it).

aiohttp, because one well-kept package gives the HTTP server, WebSockets and static files on
the asyncio loop that grpc.aio already runs on: no second server process, no ASGI layer.
"""
from __future__ import annotations

import asyncio
import json
import logging
from dataclasses import dataclass
from pathlib import Path

from aiohttp import WSMsgType, web

from landscape.supervisor.config import DashboardConfig
from landscape.supervisor.console import Console
from landscape.supervisor.device_link import DeviceLink
from landscape.supervisor.outbox import Outbox, TooSlow

log = logging.getLogger(__name__)

STATIC_DIR = Path(__file__).parent / "frontend" / "dist"
LINKS = web.AppKey("links", dict)
CONFIG = web.AppKey("config", DashboardConfig)
# WebSocket close code 1013 "try again later": the page reconnects and is sent the history.
CLOSE_TOO_SLOW = 1013


def create_app(config: DashboardConfig) -> web.Application:
    static = Path(config.static_dir) if config.static_dir else STATIC_DIR
    if not (static / "index.html").is_file():
        raise FileNotFoundError(f"the page is not built: {static / 'index.html'} is missing "
                                "(`make install` builds it with npm)")
    app = web.Application()
    app[CONFIG] = config
    app.router.add_get("/ws", _websocket)
    app.router.add_get("/api/devices", _devices)
    async def index(request: web.Request) -> web.FileResponse:
        return web.FileResponse(static / "index.html")

    app.router.add_get("/", index)
    app.router.add_static("/", static)
    app.cleanup_ctx.append(_device_links)
    return app


async def _device_links(app: web.Application):
    config = app[CONFIG]
    links = {d.name: DeviceLink(d, config.display_rate_hz, config.tls, config.token)
             for d in config.devices}
    for link in links.values():
        link.start()
    app[LINKS] = links
    yield
    await asyncio.gather(*(link.close() for link in links.values()))


async def _devices(request: web.Request) -> web.Response:
    links = request.app[LINKS]
    return web.json_response([{"name": link.name, "target": link.target} for link in links.values()])


async def _websocket(request: web.Request) -> web.WebSocketResponse:
    ws = web.WebSocketResponse(heartbeat=10.0)
    await ws.prepare(request)
    links = request.app[LINKS]
    outbox = Outbox()
    console = Console(links, outbox)
    for link in links.values():
        link.join(outbox)
    sender = asyncio.create_task(_send(ws, outbox))
    try:
        async for message in ws:
            if message.type is not WSMsgType.TEXT:
                continue
            try:
                body = json.loads(message.data)
            except json.JSONDecodeError:
                continue   # not a frame of ours; nothing to answer it with
            if isinstance(body, dict):
                console.receive(body)
    finally:
        for link in links.values():
            link.leave(outbox)
        outbox.close()
        await console.close()   # ends this page's sessions: the device's disconnect handler runs
        await sender
    return ws


async def _send(ws: web.WebSocketResponse, outbox: Outbox) -> None:
    try:
        while batch := await outbox.take():
            for text in batch:
                await ws.send_str(text)
    except TooSlow as error:
        log.warning("closing a browser's connection: %s", error)
        await ws.close(code=CLOSE_TOO_SLOW, message=b"too slow")
    except ConnectionError:
        pass   # the browser went away; the receive loop ends too


@dataclass
class RunningDashboard:
    runner: web.AppRunner
    url: str

    async def stop(self) -> None:
        await self.runner.cleanup()


async def start(config: DashboardConfig) -> RunningDashboard:
    """Serve on config.host:config.port (0 picks a free port); returns once listening."""
    runner = web.AppRunner(create_app(config), access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, config.host, config.port)
    await site.start()
    host, port = runner.addresses[0][:2]
    return RunningDashboard(runner, f"http://{host}:{port}/")
