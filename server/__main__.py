"""`python -m landscape.server`: run a device server until interrupted."""
from __future__ import annotations

import argparse
import logging
import signal
import threading

from landscape.server.app import serve
from landscape.server.config import DEFAULT_ADDRESS, DEFAULT_PORT, ServerConfig
from landscape.server.controller_link import CLOCKS


def parse_args(argv=None) -> ServerConfig:
    parser = argparse.ArgumentParser(prog="landscape-device-server", description=__doc__)
    parser.add_argument("--address", default=DEFAULT_ADDRESS,
                        help="address to listen on (default %(default)s: loopback only)")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT,
                        help="port to listen on, 0 for any free one (default %(default)s)")
    parser.add_argument("--cell", default=None,
                        help="cell file (TOML) describing arm, world and I/O (default: built-in)")
    parser.add_argument("--clock", choices=CLOCKS, default="realtime",
                        help="realtime: 4 ms cycle process; lockstep: as fast as possible")
    parser.add_argument("--paths", default="var/paths.sqlite3",
                        help="SQLite file keeping the named paths across restarts "
                             "(default %(default)s)")
    parser.add_argument("--max-streams", type=int, default=ServerConfig.max_streams,
                        help="most open sessions, subscriptions and jogs at once "
                             "(default %(default)s)")
    args = parser.parse_args(argv)
    return ServerConfig(address=args.address, port=args.port, cell=args.cell, clock=args.clock,
                        paths_file=args.paths, max_streams=args.max_streams,
                        max_workers=args.max_streams + 32)


def main(argv=None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    running = serve(parse_args(argv))
    print(f"landscape device server listening on {running.target}", flush=True)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    stop.wait()
    running.stop()


if __name__ == "__main__":
    main()
