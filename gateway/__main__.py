"""`python -m landscape.gateway`: the CRCL gateway in front of one device server.

    python -m landscape.gateway --device 127.0.0.1:50051 --port 64444
"""
from __future__ import annotations

import argparse
import asyncio
import logging
import signal

from landscape.client import credentials
from landscape.gateway.device import DeviceLink
from landscape.gateway.schemas import SchemaSet, default_directory
from landscape.gateway.server import DEFAULT_PORT, Gateway
from landscape.gateway.session import GatewayOptions
from landscape.gateway.status import DEFAULT_GRIPPER_STROKE
from landscape.gateway.wire import DEFAULT_MAX_DOCUMENT


def arguments(argv=None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(prog="python -m landscape.gateway", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--device", default="127.0.0.1:50051", help="the device server")
    parser.add_argument("--host", default="127.0.0.1",
                        help="address to listen on (loopback unless exposed on purpose)")
    parser.add_argument("--port", type=int, default=DEFAULT_PORT, help="CRCL TCP port (0: any)")
    parser.add_argument("--grpc-port", type=int, default=None,
                        help="also serve CrclService (gRPC) on this port (0: any)")
    parser.add_argument("--schemas", default=None,
                        help="folder of the CRCL XSDs (default: $LANDSCAPE_CRCL_SCHEMAS, else "
                             "../shared/crcl/xsd if present); 'none' to skip schema validation")
    parser.add_argument("--max-document", type=int, default=DEFAULT_MAX_DOCUMENT,
                        help="largest accepted document, bytes")
    parser.add_argument("--gripper-stroke", type=float, default=DEFAULT_GRIPPER_STROKE,
                        help="the gripper's opening in m, for GripperStatus")
    parser.add_argument("--state-rate", type=float, default=100.0,
                        help="samples per second asked of the device's state stream")
    credentials.add_arguments(parser)
    return parser.parse_args(argv)


def schema_set(option: str | None) -> SchemaSet | None:
    if option == "none":
        return None
    directory = option or default_directory()
    return SchemaSet(directory) if directory else None


async def serve(args: argparse.Namespace, ready=None) -> None:
    link = DeviceLink(args.device, args.state_rate, *credentials.from_arguments(args))
    await link.start()
    options = GatewayOptions(schema_set(args.schemas), args.max_document, args.gripper_stroke)
    gateway = await Gateway(link, options).serve(args.host, args.port)
    grpc_server = None
    if args.grpc_port is not None:
        from landscape.gateway.grpc_face import serve_grpc
        grpc_server, grpc_port = await serve_grpc(link, options, args.host, args.grpc_port)
        print(f"CRCL gRPC face listening on {args.host}:{grpc_port}", flush=True)
    print(f"CRCL gateway listening on {args.host}:{gateway.port} "
          f"(schemas: {options.schemas.directory if options.schemas else 'none'})", flush=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for sig in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(sig, stop.set)
    await stop.wait()
    await gateway.close()
    if grpc_server is not None:
        await grpc_server.stop(1.0)
    await link.close()


def main(argv=None) -> None:
    logging.basicConfig(level=logging.INFO, format="%(asctime)s %(name)s %(levelname)s %(message)s")
    asyncio.run(serve(arguments(argv)))


if __name__ == "__main__":
    main()
