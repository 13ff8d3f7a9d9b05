"""The Foxglove bridge's process: foxglove-sdk's WebSocket server for the arms of a cell.

    python -m landscape.bridges.foxglove --device arm1=127.0.0.1:50051 [--device ...]

Off by default (the cell file's [foxglove]); on, it listens on loopback unless told: whoever
reaches it sees the cell's state, and it has no sign-in. It is read-only: it offers no client
publishing and no services; its parameters (each arm's robot_description) cannot be set.
Each arm's URDF is served three ways, for whichever the 3D panel's URDF layer is given: as
the asset `package://landscape/<arm>.urdf`, as the parameter `/<arm>/robot_description`, and
on the topic `/<arm>/robot_description`.
"""
from __future__ import annotations

import argparse
import asyncio
import logging
import signal

import foxglove
from foxglove import Capability, Parameter
from foxglove.websocket import ServerListener

from landscape.bridges.device_feed import DeviceFeed, device_targets
from landscape.bridges.foxglove.bridge import ArmBridge
from landscape.client import credentials
from landscape.server.security.tls import is_loopback

log = logging.getLogger("landscape.bridges.foxglove")

ASSET_PREFIX = "package://landscape/"
DEFAULT_PORT = 8765


class _Listener(ServerListener):
    """The parameters: each arm's robot_description, read-only (a set changes nothing and
    returns the values as they are)."""

    def __init__(self, arms: dict[str, ArmBridge]):
        self.arms = arms

    def on_get_parameters(self, client, param_names, request_id=None):
        return [p for p in self.parameters() if not param_names or p.name in param_names]

    def on_set_parameters(self, client, parameters, request_id=None):
        return self.parameters()

    def parameters(self) -> list[Parameter]:
        return [Parameter(f"/{name}/robot_description", value=arm.urdf)
                for name, arm in self.arms.items() if arm.urdf]


class FoxgloveBridge:
    """The WebSocket server and one ArmBridge per device ({name: target})."""

    def __init__(self, devices: dict[str, str], host: str = "127.0.0.1",
                 port: int = DEFAULT_PORT, rate_hz: float = 30.0, tls=None, token=None,
                 sensors: tuple[str, ...] = ("force_sensor",)):
        self.context = foxglove.Context()
        self.arms = {name: ArmBridge(name, self.context) for name in devices}
        self.feeds = [DeviceFeed(name, target, self.arms[name].callbacks(), rate_hz=rate_hz,
                                 sensors=sensors, tls=tls, token=token, client="foxglove-bridge")
                      for name, target in devices.items()]
        self.listener = _Listener(self.arms)
        self.server = foxglove.start_server(
            name="LandScape cell", host=host, port=port, context=self.context,
            capabilities=[Capability.Parameters], server_listener=self.listener,
            asset_handler=self.asset)
        self.port = self.server.port

    def asset(self, uri: str) -> bytes | None:
        """package://landscape/<arm>.urdf; nothing else is served (no file is read)."""
        if uri.startswith(ASSET_PREFIX) and uri.endswith(".urdf"):
            arm = self.arms.get(uri[len(ASSET_PREFIX):-len(".urdf")])
            if arm is not None and arm.urdf:
                return arm.urdf.encode()
        return None

    async def run(self) -> None:
        await asyncio.gather(*(feed.run() for feed in self.feeds))

    def close(self) -> None:
        for feed in self.feeds:
            feed.close()
        self.server.stop()


def parse_args(argv=None):
    parser = argparse.ArgumentParser(prog="landscape-foxglove", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", action="append", default=[], metavar="NAME=HOST:PORT",
                        help="a device server to show (repeat for each arm)")
    parser.add_argument("--host", default="127.0.0.1",
                        help="where the WebSocket server listens (default %(default)s)")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT,
                        help="its port, 0 for any free one (default %(default)s)")
    parser.add_argument("--rate", type=float, default=30.0,
                        help="state samples a second per arm (default %(default)s: what a "
                             "viewer draws; the device thins its stream to it)")
    parser.add_argument("--insecure", action="store_true",
                        help="listen off loopback all the same: anyone who reaches it sees "
                             "the cell (a network of your own only)")
    credentials.add_arguments(parser)
    args = parser.parse_args(argv)
    devices = device_targets(parser, args.device)
    if not is_loopback(args.host) and not args.insecure:
        parser.error(f"the Foxglove bridge would show the cell to anyone reaching "
                     f"{args.host}: keep it on loopback, or say --insecure")
    return args, devices


def main(argv=None) -> None:
    args, devices = parse_args(argv)
    logging.basicConfig(level=logging.INFO,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    tls, token = credentials.from_arguments(args)
    asyncio.run(_serve(args, devices, tls, token))


async def _serve(args, devices, tls, token) -> None:
    bridge = FoxgloveBridge(devices, args.host, args.port, args.rate, tls, token)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    host = f"[{args.host}]" if ":" in args.host else args.host
    print(f"Foxglove bridge on ws://{host}:{bridge.port} ({', '.join(devices)})", flush=True)
    running = asyncio.create_task(bridge.run())
    await stop.wait()
    bridge.close()
    await running
