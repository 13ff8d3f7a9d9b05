"""Health probes for a cell's services (`landscape-cell probe`), as container health checks
and tests use them: exit 0 when the service is healthy, 1 with one line saying why not.

- grpc HOST:PORT: grpc.health.v1 Check of the whole server is SERVING (the health service
  needs no token; TLS flags as every client's, landscape.client.credentials);
- tcp HOST:PORT: something accepts connections (the CRCL gateway);
- http URL: a GET answers 2xx (the web supervisor).
"""
from __future__ import annotations

import socket
import urllib.error
import urllib.request

import grpc
from grpc_health.v1 import health_pb2, health_pb2_grpc

from landscape.client.credentials import ClientTLS, open_channel


def grpc_health(target: str, tls: ClientTLS | None = None, timeout: float = 5.0) -> str | None:
    """None when SERVING, else why not."""
    try:
        with open_channel(target, tls) as channel:
            reply = health_pb2_grpc.HealthStub(channel).Check(
                health_pb2.HealthCheckRequest(service=""), timeout=timeout)
    except grpc.RpcError as error:
        return f"{target}: {error.code().name}: {error.details()}"
    if reply.status != health_pb2.HealthCheckResponse.SERVING:
        return f"{target}: {health_pb2.HealthCheckResponse.ServingStatus.Name(reply.status)}"
    return None


def tcp(target: str, timeout: float = 5.0) -> str | None:
    host, _, port = target.rpartition(":")
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout):
            return None
    except OSError as error:
        return f"{target}: {error.strerror or error}"


def http(url: str, timeout: float = 5.0) -> str | None:
    try:
        with urllib.request.urlopen(url, timeout=timeout) as reply:
            return None if 200 <= reply.status < 300 else f"{url}: HTTP {reply.status}"
    except (urllib.error.URLError, OSError) as error:
        return f"{url}: {getattr(error, 'reason', error)}"
