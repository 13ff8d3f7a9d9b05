"""`landscape-cell` (python -m landscape.cell): run a LandScape cell, and make what it needs.

    landscape-cell [--config FILE]         start every service of the cell (default: the
                                           built-in one: a device server with its simulated
                                           arm, the CRCL gateway, the web supervisor, on
                                           loopback) and watch them until Ctrl-C
    landscape-cell check [--config FILE]   read the configuration and show what would run
    landscape-cell certs [--out DIR] [--host NAME ...] [--client NAME ...]
                                           a development CA and certificates
    landscape-cell tokens [--out DIR]      a token file per role (viewer, operator, admin)
    landscape-cell probe grpc|tcp|http TARGET [TLS flags]
                                           a health check: exit 0 when healthy
"""
from __future__ import annotations

import argparse
import shlex
import sys

from landscape.cell.config import CellConfigError, load_config

COMMANDS = ("run", "check", "certs", "tokens", "probe")


def _parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="landscape-cell", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    commands = parser.add_subparsers(dest="command")
    for name in ("run", "check"):
        sub = commands.add_parser(name, help="run the cell" if name == "run"
                                  else "check the configuration, show the commands")
        sub.add_argument("--config", help="cell configuration (TOML; default: built-in)")
    certs = commands.add_parser("certs", help="a development CA and certificates")
    certs.add_argument("--out", default="var/certs", help="folder (default %(default)s)")
    certs.add_argument("--host", action="append", default=[],
                       help="another name or IP address of the device servers (repeatable)")
    certs.add_argument("--client", action="append", default=[],
                       help="a client certificate for mutual TLS (repeatable; default: client)")
    certs.add_argument("--days", type=int, default=825, help="validity (default %(default)s)")
    certs.add_argument("--new-ca", action="store_true", help="replace the CA too")
    tokens = commands.add_parser("tokens", help="a token file per role")
    tokens.add_argument("--out", default="var/tokens", help="folder (default %(default)s)")
    tokens.add_argument("--force", action="store_true", help="replace existing tokens")
    probe = commands.add_parser("probe", help="a health check")
    probe.add_argument("kind", choices=("grpc", "tcp", "http"))
    probe.add_argument("target", help="HOST:PORT, or a URL for http")
    probe.add_argument("--timeout", type=float, default=5.0)
    from landscape.client import credentials
    credentials.add_arguments(probe)
    return parser


def main(argv=None) -> None:
    argv = list(sys.argv[1:] if argv is None else argv)
    if not argv or argv[0] not in COMMANDS + ("-h", "--help"):
        argv.insert(0, "run")
    args = _parser().parse_args(argv)
    raise SystemExit(globals()[f"_{args.command}"](args))


def _load(args):
    try:
        return load_config(args.config)
    except CellConfigError as error:
        print(f"landscape-cell: {error}", file=sys.stderr)
        raise SystemExit(2) from None


def _run(args) -> int:
    from landscape.cell.launcher import run
    return run(_load(args))


def _check(args) -> int:
    from landscape.cell.services import device_service
    config = _load(args)
    print(f'cell "{config.name}" ({config.source}) is valid. Its device servers:')
    for device in config.devices:
        print(f"  {device.name}: {shlex.join(device_service(device, config.security).argv)}")
    return 0


def _certs(args) -> int:
    from landscape.cell.certs import make_certificates
    files = make_certificates(args.out, args.host, args.client or ["client"], args.days,
                              args.new_ca, opcua=True)
    print(f"CA {files.ca}; server {files.server_cert} (key {files.server_key}); clients: "
          + ", ".join(f"{name} {cert}" for name, (cert, _key) in files.clients.items())
          + f"; OPC UA server {files.opcua_server[0]}, client {files.opcua_client[0]}")
    return 0


def _tokens(args) -> int:
    from landscape.cell.tokens import make_tokens
    files = make_tokens(args.out, args.force)
    print("tokens: " + ", ".join(f"{role} {path}" for role, path in files.items()))
    return 0


def _probe(args) -> int:
    from landscape.cell import probe
    from landscape.client import credentials
    if args.kind == "grpc":
        problem = probe.grpc_health(args.target, credentials.from_arguments(args)[0],
                                    args.timeout)
    else:
        problem = getattr(probe, args.kind)(args.target, args.timeout)
    if problem:
        print(f"unhealthy: {problem}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    main()
