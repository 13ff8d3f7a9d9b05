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
import math
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

# Light modules only up here: a port in use is refused before the simulation loads (main).
from landscape.server.config import (CLOCKS, DEFAULT_ADDRESS, DEFAULT_PORT,  # noqa: E402
                                     MAX_COLLISION_MARGIN, SecurityConfig, ServerConfig)
from landscape.server.listen import listen_address, listen_problem  # noqa: E402
from landscape.server.log_text import escape_handlers  # noqa: E402

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
                        help="realtime: a 4 ms cycle process; fast: the cycle process as fast "
                             "as it goes (long programs quickly); lockstep: a thread of this "
                             "process as fast as it goes (for tests)")
    parser.add_argument("--paths", default="var/paths.sqlite3",
                        help="SQLite file keeping the named paths and the settings (speed, "
                             "acceleration, tool offset, world frame, units) across restarts "
                             "(default %(default)s)")
    parser.add_argument("--reset-settings", action="store_true",
                        help="start from the default settings instead of the stored ones")
    parser.add_argument("--settings-delay", type=float, default=None,
                        metavar="SECONDS",
                        help="an accepted setting is written to --paths within this; a server "
                             "killed outright (SIGKILL) sooner restarts without it; 0 writes "
                             "each before its reply (default 0.2 s)")
    parser.add_argument("--collision-margin", type=float,
                        default=ServerConfig.collision_margin, metavar="METRES",
                        help="no planned motion may bring two bodies of the cell closer than "
                             "this; a jog stops there (default %(default)s m)")
    parser.add_argument("--placement", default=None, metavar="X,Y,Z,ROLL,PITCH,YAW",
                        help="where the arm's base stands in a cell shared with other arms "
                             "(metres, degrees), for displays (default: nowhere)")
    parser.add_argument("--shared-cell", default="", metavar="NAME",
                        help="the name of the cell --placement places the arm in")
    _security_arguments(parser.add_argument_group(
        "security", "plaintext is for loopback: any other --address needs TLS and tokens, or "
                    "--insecure"))
    parser.add_argument("--metrics-port", type=int, default=None, metavar="PORT",
                        help="serve /metrics for Prometheus on this port (0: any free one; "
                             "default: off; the cell's launcher turns it on)")
    parser.add_argument("--metrics-address", default=DEFAULT_ADDRESS,
                        help="where /metrics listens (default %(default)s); off loopback it "
                             "is served over the server's TLS, or with --insecure")
    parser.add_argument("--log-level", default="INFO",
                        choices=["DEBUG", "INFO", "WARNING", "ERROR"],
                        help="what to log (default %(default)s); refused commands are INFO")
    args = parser.parse_args(argv)
    if bool(args.tls_cert) != bool(args.tls_key):
        parser.error("--tls-cert and --tls-key go together")
    if not 0.0 < args.collision_margin <= MAX_COLLISION_MARGIN:
        parser.error(f"--collision-margin must be above 0 and at most {MAX_COLLISION_MARGIN} m")
    if args.settings_delay is not None and not 0.0 <= args.settings_delay <= 60.0:
        parser.error("--settings-delay must be from 0 to 60 s")
    if args.mtls and not args.tls_ca:
        parser.error("--mtls needs --tls-ca (the CA that signs the clients' certificates)")
    placement = None
    if args.placement is not None:
        try:
            placement = tuple(float(v) for v in args.placement.split(","))
        except ValueError:
            placement = ()
        if len(placement) != 6 or not all(map(math.isfinite, placement)):
            parser.error(f"--placement takes six numbers X,Y,Z,ROLL,PITCH,YAW (metres, degrees), "
                         f"not {args.placement!r}")
        placement = (*placement[:3], *map(math.radians, placement[3:]))
    sized = {}
    for item in args.rate_limit_for:
        name, _, rate = item.partition("=")
        try:
            sized[name] = float(rate)
        except ValueError:
            sized[name] = 0.0
        if not name or not sized[name] > 0:
            parser.error(f"--rate-limit-for takes NAME=CALLS_PER_SECOND (above 0), not {item!r}")
    security = SecurityConfig(
        tls_cert=args.tls_cert, tls_key=args.tls_key, tls_ca=args.tls_ca, mtls=args.mtls,
        tokens=args.tokens, audit_log=args.audit_log or None,
        audit_max_bytes=args.audit_max_bytes, audit_backups=args.audit_backups,
        rate_limit=args.rate_limit or None, rate_burst=args.rate_burst, rate_limits=sized,
        insecure=args.insecure)
    config = ServerConfig(address=args.address, port=args.port, cell=args.cell,
                          clock=args.clock, paths_file=args.paths,
                          reset_settings=args.reset_settings,
                          settings_delay=args.settings_delay, security=security,
                          collision_margin=args.collision_margin,
                          max_message_bytes=args.max_message_bytes,
                          metrics_port=args.metrics_port, metrics_address=args.metrics_address,
                          placement=placement, shared_cell=args.shared_cell)
    return config, args.log_level


def _security_arguments(group) -> None:
    group.add_argument("--tls-cert", help="PEM certificate of this server (with --tls-key)")
    group.add_argument("--tls-key", help="PEM private key of --tls-cert")
    group.add_argument("--tls-ca", help="PEM CA that signs the clients' certificates (--mtls)")
    group.add_argument("--mtls", action="store_true",
                       help="mutual TLS: clients must show a certificate signed by --tls-ca")
    group.add_argument("--tokens", help="folder of viewer.tokens, operator.tokens and "
                                        "admin.tokens: callers must send one "
                                        "('authorization: Bearer <token>')")
    group.add_argument("--audit-log", default="var/audit.log",
                       help="JSON-lines log of every mutating call, refused ones included "
                            "(default %(default)s; '' for none)")
    group.add_argument("--audit-max-bytes", type=int, default=10 * 1024 * 1024,
                       help="rotate the audit log at this size (default %(default)s)")
    group.add_argument("--audit-backups", type=int, default=5,
                       help="rotated audit logs kept (default %(default)s)")
    group.add_argument("--rate-limit", type=float, default=1000.0,
                       help="calls per second one client (its token; with tokens off, its "
                            "address and client name) may make on average; stops are never "
                            "limited (default %(default)s; 0 for none)")
    group.add_argument("--rate-burst", type=int, default=2000,
                       help="calls one client may make at once (default %(default)s)")
    group.add_argument("--rate-limit-for", action="append", default=[], metavar="NAME=RATE",
                       help="calls per second the client so named may make (bursts of twice "
                            "that): a token's name, or with tokens off the name a front end "
                            "sends in landscape-client; repeat for each")
    group.add_argument("--max-message-bytes", type=int, default=4 * 1024 * 1024,
                       help="largest request accepted, bytes (default %(default)s); paths "
                            "stream in chunks, so no message needs to be big")
    group.add_argument("--insecure", action="store_true",
                       help="listen on a non-loopback address without TLS or tokens all the "
                            "same (a network of your own only)")


def main(argv=None) -> None:
    config, level = parse_args(argv)
    logging.basicConfig(level=level, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    escape_handlers()   # a caller's name or header never forges a line (log_text.py)
    problem = listen_problem(config.address, config.port)
    if problem:
        _refuse(problem)
    from landscape.server.app import StartupError, serve   # the simulation: seconds to load
    try:
        running = serve(config)
    except StartupError as error:
        _refuse(str(error))
    _say_what_runs(running, config)
    # The one "listening" line, on stdout: scripts and the cell launcher wait for it.
    print(f"landscape device server listening on {listen_address(config.address, running.port)}",
          flush=True)
    received = signal.sigwait(STOP_SIGNALS)
    log.info("%s: stopping (motion stops, drives off, lock released)",
             signal.Signals(received).name)
    running.stop()
    log.info("stopped")


def _refuse(problem: str):
    print(f"landscape-device-server: {problem}", file=sys.stderr)
    raise SystemExit(2)


def _say_what_runs(running, config: ServerConfig) -> None:
    link = running.link
    lines = [f"cell: {config.cell or 'built-in default'} ({running.device.arm.name}), "
             f"collision margin {config.collision_margin * 1000:g} mm",
             f"controller: {config.clock} clock, {link.cycle_time * 1000:g} ms cycle",
             f"paths and settings: {config.paths_file or 'in memory'}",
             f"gRPC: {listen_address(config.address, running.port)} "
             f"({_transport(config.security)})",
             f"audit log: {config.security.audit_log or 'none'}",
             f"metrics: {running.metrics.url if running.metrics else 'off'}"]
    log.info("LandScape device server\n  " + "\n  ".join(lines))
    for problem in link.tuning_problems:
        log.warning("the cycle process runs without real-time guarantees (%s): expect late "
                    "cycles under load; run as root or grant CAP_SYS_NICE for SCHED_FIFO",
                    problem)


def _transport(security: SecurityConfig) -> str:
    words = ["mutual TLS" if security.mtls else "TLS" if security.tls_enabled else "plaintext",
             "role tokens" if security.tokens else "no tokens"]
    if security.insecure:
        words.append("--insecure")
    return ", ".join(words)


if __name__ == "__main__":
    main()
