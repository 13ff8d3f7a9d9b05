"""CrclService (proto/landscape/v1/crcl_service.proto): CRCL documents over gRPC.

Each Execute call is one CrclSession, exactly as a TCP connection is; the statuses it streams
are GetStatus answers and one status per change of the current command.
"""
from __future__ import annotations

import asyncio

import grpc
from lxml import etree

from landscape.gateway.device import CrclDevice
from landscape.gateway.session import CrclSession, GatewayOptions
from landscape.v1 import crcl_service_pb2 as pb
from landscape.v1 import crcl_service_pb2_grpc


def response(status_xml: bytes) -> pb.ExecuteResponse:
    root = etree.fromstring(status_xml)
    return pb.ExecuteResponse(
        status_xml=status_xml.decode(), command_id=int(root.findtext("CommandStatus/CommandID")),
        command_state=root.findtext("CommandStatus/CommandState"),
        state_description=root.findtext("CommandStatus/StateDescription") or "")


class CrclServicer(crcl_service_pb2_grpc.CrclServiceServicer):
    def __init__(self, device: CrclDevice, options: GatewayOptions):
        self.device, self.options = device, options

    async def Execute(self, request_iterator, context):
        session = CrclSession(self.device, self.options, f"grpc {context.peer()}")
        out: asyncio.Queue = asyncio.Queue()
        last = None

        def on_change():   # the status as it is now: a quick command may end before we send
            nonlocal last
            record = session.record
            key = (id(record), record.state, record.command_id, record.program_index)
            if key != last:
                last = key
                out.put_nowait(session.status())

        session.listeners.append(on_change)

        async def read():
            try:
                async for request in request_iterator:
                    if len(request.xml) > self.options.max_document:
                        await session.refuse(f"document longer than {self.options.max_document} "
                                             f"bytes")
                        continue
                    reply = await session.receive(request.xml.encode())
                    if reply is not None:
                        out.put_nowait(reply)
                await session.wait()
            finally:
                out.put_nowait(None)

        reader = asyncio.create_task(read())
        try:
            while (item := await out.get()) is not None:
                yield response(item)
            yield response(session.status())
            await reader
        finally:
            reader.cancel()
            await session.close()


async def serve_grpc(device: CrclDevice, options: GatewayOptions, host: str, port: int,
                     credentials: grpc.ServerCredentials | None = None):
    """CrclService on host:port (0: any), over TLS with `credentials`; returns (server, port)."""
    server = grpc.aio.server()
    crcl_service_pb2_grpc.add_CrclServiceServicer_to_server(CrclServicer(device, options), server)
    address = f"{host}:{port}"
    bound = (server.add_secure_port(address, credentials) if credentials is not None
             else server.add_insecure_port(address))
    await server.start()
    return server, bound
