"""`python -m landscape.gateway`: the CRCL gateway in front of one device server.

    python -m landscape.gateway --device 127.0.0.1:50051 --port 64444

The device server's exposure rule holds here too (server/tls.py): the gateway commands the
arm with its own token for whoever reaches it, so it listens on loopback unless told
otherwise. CRCL over TCP has no authentication: a non-loopback --host needs --insecure. The
gRPC face may leave loopback with mutual TLS (--grpc-tls-cert, --grpc-tls-key and
--grpc-tls-ca: only clients with a certificate of that CA get in), or with --insecure.
"""
from __future__ import annotations

import argparse
import asyncio
import logging
import signal
import sys
from pathlib import Path

import grpc

from landscape.bridges.metrics import endpoint as metrics_endpoint
from landscape.client import Endpoint, credentials
from landscape.gateway import metrics as gateway_metrics
from landscape.gateway.device import CrclDevice
from landscape.gateway.schemas import SchemaSet, default_directory, describe
from landscape.gateway.server import DEFAULT_PORT, Gateway
from landscape.gateway.session import GatewayOptions
from landscape.gateway.status import DEFAULT_GRIPPER_STROKE
from landscape.gateway.units import ANGLE, LENGTH
from landscape.gateway.wire import DEFAULT_MAX_DOCUMENT, DOCUMENT_IDLE
from landscape.gateway.workstation import BARE, Workstation, pose_values
from landscape.server.security.tls import is_loopback

log = logging.getLogger("landscape.gateway")


def arguments(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m landscape.gateway", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="127.0.0.1:50051", help="the device server")
    parser.add_argument("--host", default="127.0.0.1",
                        help="address to listen on (loopback unless exposed on purpose)")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT, help="CRCL TCP port (0: any)")
    parser.add_argument("--grpc-port", type=int, default=None,
                        help="also serve CrclService (gRPC) on this port (0: any)")
    parser.add_argument("--grpc-host", default=None,
                        help="address of the gRPC face (default: --host)")
    parser.add_argument("--grpc-tls-cert", help="the gRPC face's PEM certificate (TLS)")
    parser.add_argument("--grpc-tls-key", help="the PEM key of --grpc-tls-cert")
    parser.add_argument("--grpc-tls-ca",
                        help="PEM CA of the client certificates the gRPC face requires (mTLS)")
    parser.add_argument("--insecure", action="store_true",
                        help="listen on non-loopback addresses all the same: whoever reaches "
                             "the gateway commands the arm (a network of your own only)")
    parser.add_argument("--schemas", default=None,
                        help="folder of NIST's CRCL XSDs (default: $LANDSCAPE_CRCL_SCHEMAS, else "
                             "those `make install` put in .tools/crcl-schemas); 'none' to skip "
                             "schema validation")
    parser.add_argument("--max-document", type=int, default=DEFAULT_MAX_DOCUMENT,
                        help="largest accepted document, bytes")
    parser.add_argument("--document-idle", type=float, default=DOCUMENT_IDLE,
                        help="seconds a started document may wait for its next bytes before "
                             "the connection is dropped")
    parser.add_argument("--gripper-stroke", type=float, default=DEFAULT_GRIPPER_STROKE,
                        help="the gripper's opening in m, for GripperStatus")
    parser.add_argument("--workstation-frame", type=_frame, default=Workstation().frame,
                        metavar='"X Y Z ROLL PITCH YAW"',
                        help="CRCL's coordinate frame in the robot's base frame, m and rad "
                             "(fixed-axis X-Y-Z); default: the base frame itself")
    parser.add_argument("--end-effector", default="",
                        help="the rack tool the arm holds from InitCanon on (fetched if need "
                             f"be), or '{BARE}' for the bare flange; default: as it is")
    parser.add_argument("--length-units", choices=LENGTH, default=Workstation.length_unit,
                        help="the length unit a CRCL program starts in")
    parser.add_argument("--angle-units", choices=ANGLE, default=Workstation.angle_unit,
                        help="the angle unit a CRCL program starts in")
    parser.add_argument("--state-rate", type=float, default=100.0,
                        help="samples per second asked of the device's state stream")
    credentials.add_arguments(parser)
    metrics_endpoint.add_arguments(parser)   # /metrics (gateway/metrics.py)
    return parser.parse_args(argv)


def _frame(text: str) -> tuple[float, ...]:
    try:
        return pose_values(text)
    except ValueError as error:
        raise argparse.ArgumentTypeError(str(error)) from None


def workstation(args: argparse.Namespace) -> Workstation:
    return Workstation(args.workstation_frame, args.end_effector, args.length_units,
                       args.angle_units)


def schema_set(option: str | None) -> SchemaSet | None:
    if option == "none":
        return None
    directory = option or default_directory()
    return SchemaSet(directory) if directory else None


def exposure_problems(args: argparse.Namespace) -> list[str]:
    """Why the gateway must not listen where `args` say (the module's rule); empty if it may."""
    if args.insecure:
        return []
    problems = []
    if not is_loopback(args.host):
        problems.append(f"refusing to serve CRCL on {args.host}: CRCL has no authentication, "
                        f"so anyone on the network could command the arm with this gateway's "
                        f"token; listen on 127.0.0.1 (a tunnel or a proxy with authentication "
                        f"in front), or pass --insecure if this network is yours alone")
    grpc_host = args.grpc_host or args.host
    if args.grpc_port is not None and not is_loopback(grpc_host) and not (
            args.grpc_tls_cert and args.grpc_tls_key and args.grpc_tls_ca):
        problems.append(f"refusing to serve the gRPC face on {grpc_host} without mutual TLS "
                        f"(--grpc-tls-cert, --grpc-tls-key, --grpc-tls-ca; `landscape-cell "
                        f"certs` makes them), or --insecure")
    return problems


def grpc_credentials(args: argparse.Namespace) -> grpc.ServerCredentials | None:
    """The gRPC face's TLS (mutual with --grpc-tls-ca), or None for plaintext."""
    if not (args.grpc_tls_cert or args.grpc_tls_key or args.grpc_tls_ca):
        return None
    if not (args.grpc_tls_cert and args.grpc_tls_key):
        raise ValueError("the gRPC face's TLS needs --grpc-tls-cert and --grpc-tls-key")
    pair = (Path(args.grpc_tls_key).read_bytes(), Path(args.grpc_tls_cert).read_bytes())
    ca = Path(args.grpc_tls_ca).read_bytes() if args.grpc_tls_ca else None
    return grpc.ssl_server_credentials([pair], ca, require_client_auth=ca is not None)


async def serve(args: argparse.Namespace, ready=None) -> None:
    schemas = schema_set(args.schemas)
    log.log(logging.INFO if schemas else logging.WARNING, "validating CRCL documents against %s",
            describe(schemas))
    log.info("workstation: %s", workstation(args).describe())
    device = CrclDevice(Endpoint(args.device, *credentials.from_arguments(args)), args.state_rate)
    await device.start()
    options = GatewayOptions(schemas, args.max_document, args.document_idle,
                             args.gripper_stroke, workstation(args))
    gateway = await Gateway(device, options).serve(args.host, args.port)
    grpc_server = None
    if args.grpc_port is not None:
        from landscape.gateway.grpc_face import serve_grpc
        host = args.grpc_host or args.host
        grpc_server, grpc_port = await serve_grpc(device, options, host, args.grpc_port,
                                                  grpc_credentials(args))
        print(f"CRCL gRPC face listening on {host}:{grpc_port}", flush=True)
    print(f"CRCL gateway listening on {args.host}:{gateway.port}", flush=True)
    metrics = gateway_metrics.start(args, gateway)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    await stop.wait()
    if metrics is not None:
        metrics.close()
    await gateway.close()
    if grpc_server is not None:
        await grpc_server.stop(1.0)
    await device.close()


def main(argv=None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    args = arguments(argv)
    problems = exposure_problems(args)
    try:
        grpc_credentials(args)
    except (OSError, ValueError) as error:
        problems.append(f"the gRPC face's TLS: {error}")
    if problems:
        for problem in problems:
            print(f"landscape-crcl-gateway: {problem}", file=sys.stderr)
        raise SystemExit(2)
    asyncio.run(serve(args))


if __name__ == "__main__":
    main()
