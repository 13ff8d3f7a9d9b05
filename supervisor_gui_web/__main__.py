"""`python -m landscape.supervisor --device arm1=127.0.0.1:50051 --port 8080`"""
from __future__ import annotations

import argparse
import asyncio
import ipaddress
import logging
import signal
import socket

from landscape.client import credentials
from landscape.supervisor import app
from landscape.supervisor.config import (DEFAULT_DISPLAY_RATE_HZ, DEFAULT_HOST, DEFAULT_PORT,
                                         DashboardConfig, parse_device)


def _device(text: str):
    try:
        return parse_device(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def parse_args(argv=None) -> DashboardConfig:
    parser = argparse.ArgumentParser(prog="python -m landscape.supervisor",
                                     description="The LandScape web supervisor (dashboard).")
    parser.add_argument("--device", type=_device, action="append", required=True,
                        metavar="NAME=HOST:PORT", help="a device server to show (repeatable)")
    parser.add_argument("--host", default=DEFAULT_HOST,
                        help="address to serve the page on (default: loopback only)")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT, help="0 picks a free port")
    parser.add_argument("--display-rate", type=float, default=DEFAULT_DISPLAY_RATE_HZ,
                        help="state samples per second sent to the page")
    credentials.add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        tls, token = credentials.from_arguments(args)
        return DashboardConfig(devices=tuple(args.device), host=args.host, port=args.port,
                               display_rate_hz=args.display_rate, tls=tls,
                               token=token)
    except (OSError, ValueError) as error:
        parser.error(str(error))


def _loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:   # a name: loopback if every address it has is
        return all(ipaddress.ip_address(info[4][0]).is_loopback
                   for info in socket.getaddrinfo(host, None))


async def serve(config: DashboardConfig) -> None:
    running = await app.start(config)
    print(f"web supervisor on {running.url}", flush=True)
    if not _loopback(config.host):
        logging.warning("serving beyond loopback without TLS or login: whoever reaches %s can "
                        "command the devices through it", running.url)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    await stop.wait()
    await running.stop()


def main(argv=None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    asyncio.run(serve(parse_args(argv)))


if __name__ == "__main__":
    main()
