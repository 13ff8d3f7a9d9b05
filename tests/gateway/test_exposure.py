"""The gateway keeps off the network unless told (the device server's exposure rule), and its
gRPC face speaks mutual TLS when given certificates."""
from __future__ import annotations

import subprocess
import sys

import grpc
import pytest

from landscape.cell.certs import make_certificates
from landscape.gateway.__main__ import arguments, exposure_problems, grpc_credentials
from landscape.gateway.grpc_face import serve_grpc
from landscape.v1 import crcl_service_pb2 as pb
from landscape.v1 import crcl_service_pb2_grpc

from crcl_support import check_status, command

GATEWAY = [sys.executable, "-m", "landscape.gateway", "--device", "127.0.0.1:1", "--port", "0"]


def test_a_non_loopback_address_is_refused_without_insecure():
    refused = subprocess.run([*GATEWAY, "--host", "0.0.0.0"], capture_output=True, text=True,
                             timeout=60)
    assert refused.returncode == 2
    assert "refusing to serve CRCL on 0.0.0.0: CRCL has no authentication" in refused.stderr
    assert "listening" not in refused.stdout


def test_insecure_listens_where_it_is_told():
    gateway = subprocess.Popen([*GATEWAY, "--host", "0.0.0.0", "--insecure"],
                               stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        assert "CRCL gateway listening on 0.0.0.0:" in gateway.stdout.readline()
    finally:
        gateway.terminate()
        gateway.wait(timeout=20)


@pytest.mark.parametrize("flags, problems", [
    ([], 0),
    (["--grpc-port", "0"], 0),
    (["--host", "10.1.2.3"], 1),
    (["--host", "10.1.2.3", "--grpc-port", "0"], 2),
    (["--grpc-host", "10.1.2.3", "--grpc-port", "0"], 1),
    (["--grpc-host", "10.1.2.3", "--grpc-port", "0", "--grpc-tls-cert", "c", "--grpc-tls-key",
      "k"], 1),                                          # TLS alone lets anyone in
    (["--grpc-host", "10.1.2.3", "--grpc-port", "0", "--grpc-tls-cert", "c", "--grpc-tls-key",
      "k", "--grpc-tls-ca", "ca"], 0),                   # mutual TLS
    (["--host", "10.1.2.3", "--grpc-port", "0", "--insecure"], 0),
])
def test_the_exposure_rule(flags, problems):
    assert len(exposure_problems(arguments(flags))) == problems


def test_the_grpc_face_with_mutual_tls(gateway, tmp_path):
    certs = make_certificates(tmp_path, clients=("client",))
    client_cert, client_key = certs.clients["client"]
    args = arguments(["--grpc-tls-cert", str(certs.server_cert), "--grpc-tls-key",
                      str(certs.server_key), "--grpc-tls-ca", str(certs.ca)])
    server, port = gateway.run(serve_grpc(gateway.link, gateway.options, "127.0.0.1", 0,
                                          grpc_credentials(args)))
    ca = certs.ca.read_bytes()
    try:
        with grpc.secure_channel(f"localhost:{port}", grpc.ssl_channel_credentials(
                ca, client_key.read_bytes(), client_cert.read_bytes())) as channel:
            replies = list(crcl_service_pb2_grpc.CrclServiceStub(channel).Execute(
                iter([pb.ExecuteRequest(xml=command("GetStatus", 1).decode())]), timeout=30))
        check_status(replies[0].status_xml.encode())
        for credentials in (grpc.ssl_channel_credentials(ca), None):   # no client certificate
            channel = (grpc.secure_channel(f"localhost:{port}", credentials) if credentials
                       else grpc.insecure_channel(f"127.0.0.1:{port}"))
            with channel, pytest.raises(grpc.RpcError) as refused:
                list(crcl_service_pb2_grpc.CrclServiceStub(channel).Execute(
                    iter([pb.ExecuteRequest(xml=command("GetStatus", 1).decode())]), timeout=10))
            assert refused.value.code() is grpc.StatusCode.UNAVAILABLE
    finally:
        gateway.run(server.stop(None))
