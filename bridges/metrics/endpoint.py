"""/metrics on a port of its own, served by prometheus-client's HTTP server on a thread.

What it serves are read-only figures, so it is on by default, on loopback. Off loopback it
needs TLS (the service's certificate; with a CA, scrapers must show a certificate signed by
it), or `insecure` for a network of one's own: the figures say what the cell does and when.
Every figure is read when scraped; nothing here runs between scrapes.
"""
from __future__ import annotations

import argparse
from dataclasses import dataclass

from prometheus_client import CollectorRegistry, ProcessCollector, start_http_server

from landscape.server.security.tls import is_loopback


@dataclass(frozen=True)
class MetricsTLS:
    """PEM files: the endpoint's certificate and key; ca: scrapers must show a certificate it
    signed (None: any scraper)."""

    cert: str
    key: str
    ca: str | None = None


class MetricsExposed(ValueError):
    """An endpoint that would serve off loopback in plaintext; the message names the fix."""


@dataclass
class MetricsEndpoint:
    address: str
    port: int
    _server: object
    _thread: object

    @property
    def url(self) -> str:
        host = f"[{self.address}]" if ":" in self.address else self.address
        return f"http://{host}:{self.port}/metrics"

    def close(self) -> None:
        self._server.shutdown()
        self._server.server_close()
        self._thread.join(5.0)


def new_registry() -> CollectorRegistry:
    """A registry with the process's own figures (process_resident_memory_bytes, CPU, open
    files): each service has its own, never prometheus-client's global one."""
    registry = CollectorRegistry()
    ProcessCollector(registry=registry)
    return registry


def exposure_problem(address: str, tls: MetricsTLS | None, insecure: bool) -> str | None:
    if is_loopback(address) or tls is not None or insecure:
        return None
    return (f"/metrics would be served on {address} in plaintext: give it TLS (the service's "
            f"certificate), keep it on loopback, or say insecure on a network of your own")


def serve_metrics(registry: CollectorRegistry, address: str = "127.0.0.1", port: int = 0,
                  tls: MetricsTLS | None = None, insecure: bool = False) -> MetricsEndpoint:
    """Serve `registry` at http(s)://address:port/metrics (port 0: any free one).
    MetricsExposed off loopback without TLS or `insecure`; OSError if the port is taken."""
    problem = exposure_problem(address, tls, insecure)
    if problem:
        raise MetricsExposed(problem)
    options = {} if tls is None else {"certfile": tls.cert, "keyfile": tls.key,
                                      "client_cafile": tls.ca,
                                      "client_auth_required": tls.ca is not None}
    server, thread = start_http_server(port, address.strip("[]"), registry, **options)
    return MetricsEndpoint(address, server.server_address[1], server, thread)


def add_arguments(parser: argparse.ArgumentParser) -> None:
    """--metrics-port, --metrics-host and --metrics-insecure, for a front end (the gateway,
    the supervisor)."""
    parser.add_argument("--metrics-port", type=int, default=None, metavar="PORT",
                        help="serve /metrics for Prometheus on this port (0: any free one; "
                             "default: off; the cell's launcher turns it on)")
    parser.add_argument("--metrics-host", default="127.0.0.1",
                        help="where /metrics listens (default %(default)s)")
    parser.add_argument("--metrics-insecure", action="store_true",
                        help="serve /metrics off loopback in plaintext, on a network of your "
                             "own (a container's, published on the host's loopback)")


def options(argv=None) -> tuple[argparse.Namespace, list[str]]:
    """(--metrics-port and --metrics-host, the other arguments) of a command line."""
    parser = argparse.ArgumentParser(add_help=False)
    add_arguments(parser)
    return parser.parse_known_args(argv)
