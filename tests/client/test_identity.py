"""Who a call comes from (identity.py): any name travels in a gRPC header, cut to 128
characters, and reads back as it was; no newline or escape reaches the server raw."""
from __future__ import annotations

import urllib.parse
from concurrent import futures

import grpc

from landscape.client.identity import MAX_CHARACTERS, Identity
from landscape.v1 import control_pb2, device_service_pb2_grpc


class _Recorder(grpc.GenericRpcHandler):
    def __init__(self):
        self.metadata: list[dict] = []

    def service(self, details):
        self.metadata.append(dict(details.invocation_metadata))
        return None            # UNIMPLEMENTED: the headers are all this server wants


def test_any_name_travels_and_reads_back_as_it_was():
    name = "jörg\n\x1b[31m@cell 7 100%"          # a newline and an ANSI escape: no forged lines
    recorder = _Recorder()
    server = grpc.server(futures.ThreadPoolExecutor(max_workers=2), handlers=[recorder])
    port = server.add_insecure_port("127.0.0.1:0")
    server.start()
    try:
        with grpc.insecure_channel(f"127.0.0.1:{port}") as channel:
            stub = device_service_pb2_grpc.DeviceServiceStub(channel)
            try:
                stub.GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=5,
                                    metadata=Identity("supervisor", name).metadata())
            except grpc.RpcError as error:      # unmodified names fail: "Invalid metadata"
                assert error.code() is grpc.StatusCode.UNIMPLEMENTED, error
    finally:
        server.stop(grace=None)
    sent = recorder.metadata[0]
    assert sent["landscape-client"] == "supervisor"
    assert "\n" not in sent["landscape-on-behalf-of"] and "\x1b" not in sent["landscape-on-behalf-of"]
    assert urllib.parse.unquote(sent["landscape-on-behalf-of"]) == name


def test_a_long_name_is_cut_and_a_program_acting_for_itself_says_no_one():
    long = Identity("p", "x" * 500).metadata()
    assert len(urllib.parse.unquote(dict(long)["landscape-on-behalf-of"])) == MAX_CHARACTERS
    assert dict(Identity("p").metadata()) == {"landscape-client": "p"}
