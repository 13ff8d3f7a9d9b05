"""The CRCL gateway's /metrics (bridges/metrics/endpoint.py): its process (memory, CPU, open
files) and the CRCL connections it holds, read when scraped."""
from __future__ import annotations

from prometheus_client.core import GaugeMetricFamily

from landscape.bridges.metrics.endpoint import MetricsEndpoint, new_registry, serve_metrics


class _Connections:
    def __init__(self, count):
        self.count = count

    def collect(self):
        yield GaugeMetricFamily("landscape_crcl_connections", "CRCL connections open",
                                value=self.count())


def start(args, gateway) -> MetricsEndpoint | None:
    """/metrics as --metrics-port and --metrics-host say (None when off); off loopback only
    with --insecure, as CRCL itself."""
    if args.metrics_port is None:
        return None
    registry = new_registry()
    registry.register(_Connections(lambda: len(gateway.connections)))
    endpoint = serve_metrics(registry, args.metrics_host, args.metrics_port,
                             insecure=args.insecure or args.metrics_insecure)
    print(f"CRCL gateway metrics on {endpoint.url}", flush=True)
    return endpoint
