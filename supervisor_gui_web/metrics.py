"""The web supervisor's /metrics (bridges/metrics/endpoint.py): its process (memory, CPU,
open files), the people signed in and their pages, and whether each device answers; read
when scraped. Loopback only unless --metrics-insecure says the network is its own: the
supervisor has no TLS of its own."""
from __future__ import annotations

from typing import Callable

from prometheus_client.core import GaugeMetricFamily
from prometheus_client.registry import Collector

from landscape.bridges.metrics.endpoint import MetricsEndpoint, new_registry, serve_metrics


class _Supervisor(Collector):
    def __init__(self, people: Callable[[], dict[str, int]], pages: Callable[[], int],
                 devices: Callable[[], dict[str, bool]]):
        self.people, self.pages, self.devices = people, pages, devices

    def collect(self):
        signed_in = GaugeMetricFamily("landscape_supervisor_sign_ins",
                                      "people signed in, by role", labels=["role"])
        for role, count in sorted(self.people().items()):
            signed_in.add_metric([role], count)
        yield signed_in
        yield GaugeMetricFamily("landscape_supervisor_pages", "supervisor pages open",
                                value=self.pages())
        answering = GaugeMetricFamily("landscape_supervisor_device_answering",
                                      "1 while every feed of the device answers the supervisor",
                                      labels=["device"])
        for name, ok in self.devices().items():
            answering.add_metric([name], 1.0 if ok else 0.0)
        yield answering


def start(options, people: Callable[[], dict[str, int]], pages: Callable[[], int],
          devices: Callable[[], dict[str, bool]]) -> MetricsEndpoint | None:
    """/metrics as --metrics-port, --metrics-host and --metrics-insecure say
    (endpoint.options), None when off; `people`, `pages` and `devices` are read per scrape."""
    if options.metrics_port is None:
        return None
    registry = new_registry()
    registry.register(_Supervisor(people, pages, devices))
    endpoint = serve_metrics(registry, options.metrics_host, options.metrics_port,
                             insecure=options.metrics_insecure)
    print(f"web supervisor metrics on {endpoint.url}", flush=True)
    return endpoint
