"""`python -m landscape.supervisor --device arm1=127.0.0.1:50051 --sign-in-tokens var/tokens`"""
from __future__ import annotations

import argparse
import asyncio
import ipaddress
import logging
import signal
import socket

from landscape.bridges.metrics.endpoint import options as metrics_options
from landscape.client import credentials
from landscape.server.security.auth import TokenStore
from landscape.supervisor import app, metrics
from landscape.supervisor.config import (DEFAULT_DISPLAY_RATE_HZ, DEFAULT_HOST, DEFAULT_PORT,
                                         DashboardConfig, parse_device)
from landscape.supervisor.origins import own_origins
from landscape.supervisor.sign_in import DEFAULT_IDLE_S, DEFAULT_MAX_AGE_S


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
    people = parser.add_argument_group("signing in")
    people.add_argument("--sign-in-tokens", required=True, metavar="DIR",
                        help="folder of the role tokens people sign in with (viewer.tokens, "
                             "operator.tokens, admin.tokens: `landscape-cell tokens`)")
    people.add_argument("--allowed-origin", action="append", default=[], metavar="URL",
                        help="another front end's origin allowed to use the supervisor, "
                             "scheme://host[:port] (repeatable; its own is always allowed)")
    people.add_argument("--sign-in-idle", type=float, default=DEFAULT_IDLE_S, metavar="S",
                        help="seconds a sign-in lasts with no request and no page open "
                             "(default %(default)g)")
    people.add_argument("--sign-in-max-age", type=float, default=DEFAULT_MAX_AGE_S, metavar="S",
                        help="seconds a sign-in lasts at most (default %(default)g)")
    credentials.add_arguments(parser)
    args = parser.parse_args(argv)
    try:
        tls, token = credentials.from_arguments(args)
        TokenStore.load(args.sign_in_tokens)   # TokenFileError names the file and line
        return DashboardConfig(devices=tuple(args.device), host=args.host, port=args.port,
                               display_rate_hz=args.display_rate, tls=tls, token=token,
                               sign_in_tokens=args.sign_in_tokens,
                               allowed_origins=tuple(args.allowed_origin),
                               sign_in_idle_s=args.sign_in_idle,
                               sign_in_max_age_s=args.sign_in_max_age)
    except (OSError, ValueError) as error:
        parser.error(str(error))


def _loopback(host: str) -> bool:
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:   # a name: loopback if every address it has is
        return all(ipaddress.ip_address(info[4][0]).is_loopback
                   for info in socket.getaddrinfo(host, None))


async def serve(config: DashboardConfig, metrics_on=None) -> None:
    running = await app.start(config)
    print(f"web supervisor on {running.url}", flush=True)
    endpoint = metrics.start(metrics_on, running.sign_ins.by_role, running.sign_ins.pages,
                             running.devices_answering) if metrics_on else None
    print(f"sign in with a token from {config.sign_in_tokens} (operator.tokens to command, "
          f"viewer.tokens to watch)", flush=True)
    if not _loopback(config.host):
        logging.warning("serving beyond loopback over plain HTTP: sign-in tokens and cookies "
                        "cross the network readable; put TLS in front of %s", running.url)
        if not config.allowed_origins:
            logging.warning("pages are accepted from %s only: list the URL people use in "
                            "--allowed-origin ([supervisor] allowed_origins)",
                            ", ".join(own_origins(config.host, int(running.url.rstrip("/")
                                                                   .rsplit(":", 1)[1]))))
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    await stop.wait()
    if endpoint is not None:
        endpoint.close()
    await running.stop()


def main(argv=None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(levelname)s %(name)s: %(message)s")
    metrics_on, argv = metrics_options(argv)   # --metrics-port, -host, -insecure
    asyncio.run(serve(parse_args(argv), metrics_on))


if __name__ == "__main__":
    main()
