"""`python -m landscape.server`: run a device server until SIGINT, SIGTERM or SIGHUP.

Any of the three stops the server the safe way: the motion stops along its path, the drives
go off, the lock is released, stored paths stay stored, and the process exits 0. The signals
are blocked in every thread and taken by the main thread with sigwait, so no handler ever
runs in the middle of other code (a handler re-entering a lock was how a SIGTERM could hang
the server); a second signal during the stop changes nothing.
"""
from __future__ import annotations

import argparse
import logging
import os
import signal
import sys
from multiprocessing import resource_tracker

# gRPC's core logs its own copy of errors the server reports itself (a port in use, say);
# GRPC_VERBOSITY=ERROR (or DEBUG) brings them back.
os.environ.setdefault("GRPC_VERBOSITY", "NONE")

# Before anything starts a thread (numpy's import starts its BLAS threads): threads inherit
# the mask, so the stop signals can only be taken by the sigwait in main(). The resource
# tracker, which multiprocessing starts with the first process, unblocks SIGINT and SIGTERM
# when it starts: start it first.
STOP_SIGNALS = {signal.SIGINT, signal.SIGTERM, signal.SIGHUP}
resource_tracker.ensure_running()
signal.pthread_sigmask(signal.SIG_BLOCK, STOP_SIGNALS)

from landscape.server.app import StartupError, listen_address, serve  # noqa: E402
from landscape.server.config import DEFAULT_ADDRESS, DEFAULT_PORT, ServerConfig  # noqa: E402
from landscape.server.controller_link import CLOCKS  # noqa: E402

log = logging.getLogger("landscape.server")


def parse_args(argv=None) -> tuple[ServerConfig, str]:
    parser = argparse.ArgumentParser(prog="landscape-device-server", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--address", default=DEFAULT_ADDRESS,
                        help="address to listen on (default %(default)s: loopback only); "
                             "IPv6 as ::1 or [::1]")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT,
                        help="port to listen on, 0 for any free one (default %(default)s)")
    parser.add_argument("--cell", default=None,
                        help="cell file (TOML) describing arm, world and I/O (default: built-in)")
    parser.add_argument("--clock", choices=CLOCKS, default="realtime",
                        help="realtime: 4 ms cycle process; lockstep: as fast as possible")
    parser.add_argument("--paths", default="var/paths.sqlite3",
                        help="SQLite file keeping the named paths and the settings (speed, "
                             "acceleration, tool offset, world frame, units) across restarts "
                             "(default %(default)s)")
    parser.add_argument("--reset-settings", action="store_true",
                        help="start from the default settings instead of the stored ones")
    parser.add_argument("--log-level", default="INFO",
                        choices=["DEBUG", "INFO", "WARNING", "ERROR"],
                        help="what to log (default %(default)s); refused commands are INFO")
    args = parser.parse_args(argv)
    config = ServerConfig(address=args.address, port=args.port, cell=args.cell,
                          clock=args.clock, paths_file=args.paths,
                          reset_settings=args.reset_settings)
    return config, args.log_level


def main(argv=None) -> None:
    config, level = parse_args(argv)
    logging.basicConfig(level=level, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    try:
        running = serve(config)
    except StartupError as error:
        print(f"landscape-device-server: {error}", file=sys.stderr)
        raise SystemExit(2) from None
    _say_what_runs(running, config)
    print(f"landscape device server listening on {listen_address(config.address, running.port)}",
          flush=True)
    received = signal.sigwait(STOP_SIGNALS)
    log.info("%s: stopping (motion stops, drives off, lock released)",
             signal.Signals(received).name)
    running.stop()
    log.info("stopped")


def _say_what_runs(running, config: ServerConfig) -> None:
    link = running.link
    lines = [f"cell: {config.cell or 'built-in default'} ({running.device.arm.name})",
             f"controller: {config.clock} clock, {link.cycle_time * 1000:g} ms cycle",
             f"paths and settings: {config.paths_file or 'in memory'}",
             f"listening: {listen_address(config.address, running.port)} (plaintext gRPC)"]
    log.info("LandScape device server\n  " + "\n  ".join(lines))
    for problem in link.tuning_problems:
        log.warning("the cycle process runs without real-time guarantees (%s): expect late "
                    "cycles under load; run as root or grant CAP_SYS_NICE for SCHED_FIFO",
                    problem)


if __name__ == "__main__":
    main()
