"""The web supervisor's /metrics (bridges/metrics/endpoint.py): its process (memory, CPU,
open files), read when scraped. Loopback only: the supervisor has no TLS of its own."""
from __future__ import annotations

from landscape.bridges.metrics.endpoint import MetricsEndpoint, new_registry, serve_metrics


def start(options) -> MetricsEndpoint | None:
    """/metrics as --metrics-port and --metrics-host say (endpoint.options), None when off."""
    if options.metrics_port is None:
        return None
    endpoint = serve_metrics(new_registry(), options.metrics_host, options.metrics_port)
    print(f"web supervisor metrics on {endpoint.url}", flush=True)
    return endpoint
