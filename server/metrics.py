"""The device server's figures for Prometheus, served at /metrics (bridges/metrics/endpoint.py).

Nearly everything is read when scraped, so the cell pays for /metrics only while it is on:

- the cycle: period and lateness histograms, cycles, overruns and missed deadlines, from the
  real-time clock's shared-memory statistics (server/cycle/stats.py): each scrape bins the
  cycles run since the last one, so the histograms are Prometheus's usual cumulative ones and
  the cycle process never knows;
- the device: its state (one gauge per state), the e-stop, sessions, open streams, event
  subscribers, and queue depths (calls in flight per thread-pool lane, the audit's backlog);
- memory: this process's (process_*) and the cycle process's (landscape_cycle_process_*).

Counted as they happen, only while /metrics is on: RPC latency by method and status code (the
security interceptor's `timing`), planning time (the planner and the planning process
wrapped in a timer), alarms by code and lock hand-overs (a subscriber of the event bus).
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np
from prometheus_client import CollectorRegistry, Counter, Histogram, ProcessCollector
from prometheus_client.core import (CounterMetricFamily, GaugeMetricFamily,
                                    HistogramMetricFamily)

from landscape.server.device import states
from landscape.server.events.records import Alarm, StateChange

# s: cycle period around its 4 ms, lateness from 10 us to a whole cycle late and beyond
PERIOD_BUCKETS = (0.0035, 0.0039, 0.00399, 0.004, 0.00401, 0.0041, 0.0045, 0.005, 0.006, 0.008,
                  0.012, 0.02)
LATE_BUCKETS = (1e-5, 2.5e-5, 5e-5, 1e-4, 2.5e-4, 5e-4, 1e-3, 2e-3, 4e-3, 8e-3, 0.016)
RPC_BUCKETS = (0.0001, 0.00025, 0.0005, 0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25,
               0.5, 1.0, 2.5, 5.0, 10.0, 30.0)
PLANNING_BUCKETS = (0.001, 0.0025, 0.005, 0.01, 0.025, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0,
                    10.0, 30.0)
LOCKED = {s.value for s in states.LOCKED}


class CycleCollector:
    """Cumulative histograms of the cycle's period and lateness from a window of samples
    `samples(since)` -> (cycles, overruns, missed, period (k,), late (k,)) gives: those after
    cycle number `since` that the window still holds (None: the clock keeps no statistics,
    the lock-step one)."""

    def __init__(self, samples: Callable[[int], tuple | None]):
        self.samples = samples
        self._lock = threading.Lock()
        self._seen = 0
        self._counts = {"period": np.zeros(len(PERIOD_BUCKETS) + 1, dtype=np.int64),
                        "late": np.zeros(len(LATE_BUCKETS) + 1, dtype=np.int64)}
        self._sums = {"period": 0.0, "late": 0.0}
        self._totals = (0, 0, 0)

    def _update(self) -> bool:
        got = self.samples(self._seen)
        if got is not None and got[0] < self._seen:   # the statistics started afresh
            self._seen = 0
            got = self.samples(0)
        if got is None:
            return False
        cycles, overruns, missed, period, late = got
        for name, values, bounds in (("period", period[np.isfinite(period)], PERIOD_BUCKETS),
                                     ("late", late, LATE_BUCKETS)):
            self._counts[name] += np.bincount(np.searchsorted(bounds, values, side="left"),
                                              minlength=len(bounds) + 1)
            self._sums[name] += float(values.sum())
        self._seen, self._totals = cycles, (cycles, overruns, missed)
        return True

    def collect(self):
        with self._lock:
            if not self._update():
                return
            for name, bounds, text in (
                    ("period", PERIOD_BUCKETS, "time between the starts of consecutive cycles"),
                    ("late", LATE_BUCKETS, "start of a cycle after its deadline")):
                cumulative = np.cumsum(self._counts[name]).tolist()
                buckets = [(repr(b), c) for b, c in zip(bounds, cumulative)]
                buckets.append(("+Inf", cumulative[-1]))
                yield HistogramMetricFamily(f"landscape_cycle_{name}_seconds", text,
                                            buckets=buckets, sum_value=self._sums[name])
            for name, value, text in zip(
                    ("cycles", "cycle_overruns", "cycle_missed_deadlines"), self._totals,
                    ("cycles run", "cycles that started more than a period late",
                     "deadlines skipped after an overrun")):
                yield CounterMetricFamily(f"landscape_{name}", text, value=value)


class DeviceCollector:
    """The device's gauges, each a callable read at scrape time."""

    def __init__(self, state: Callable[[], tuple[str, bool]], sessions: Callable[[], int],
                 streams: Callable[[str], int], subscribers: Callable[[], int],
                 queues: Callable[[], dict[str, int]]):
        self.state, self.sessions, self.streams = state, sessions, streams
        self.subscribers, self.queues = subscribers, queues

    def collect(self):
        current, estop = self.state()
        family = GaugeMetricFamily("landscape_device_state", "1 for the state the device is in",
                                   labels=["state"])
        for state in states.State:
            family.add_metric([state.value], 1.0 if state.value == current else 0.0)
        yield family
        yield GaugeMetricFamily("landscape_estop", "1 while the e-stop is pressed",
                                value=1.0 if estop else 0.0)
        yield GaugeMetricFamily("landscape_sessions", "sessions open", value=self.sessions())
        streams = GaugeMetricFamily("landscape_streams", "streams open, by kind",
                                    labels=["kind"])
        for kind in ("session", "watch"):
            streams.add_metric([kind], self.streams(kind))
        yield streams
        yield GaugeMetricFamily("landscape_event_subscribers", "event bus subscribers",
                                value=self.subscribers())
        depths = GaugeMetricFamily("landscape_queue_depth", "work waiting or running, by queue",
                                   labels=["queue"])
        for name, depth in self.queues().items():
            depths.add_metric([name], depth)
        yield depths


class DeviceMetrics:
    """Every figure of one device server, in `registry`. `rpc_timing` is the interceptor's
    timing hook; `time_planning(target, methods)` wraps a planner; `watch(bus)` counts the
    alarms and lock hand-overs on the event bus until `close`."""

    def __init__(self, registry: CollectorRegistry, *, cycle_samples, cycle_pid, state, sessions,
                 streams, subscribers, queues):
        self.registry = registry
        registry.register(CycleCollector(cycle_samples))
        registry.register(DeviceCollector(state, sessions, streams, subscribers, queues))
        ProcessCollector(namespace="landscape_cycle", pid=lambda: cycle_pid() or "none",
                         registry=registry)
        self.rpc = Histogram("landscape_rpc_duration_seconds",
                             "unary calls, from arrival to reply, by method and status code",
                             ["method", "code"], buckets=RPC_BUCKETS, registry=registry)
        self.planning = Histogram("landscape_planning_seconds",
                                  "planning a motion (IK, TOPP-RA, the collision check)",
                                  ["kind"], buckets=PLANNING_BUCKETS, registry=registry)
        self.alarms = Counter("landscape_alarms", "alarms raised, by code and severity",
                              ["code", "severity"], registry=registry)
        self.lock = Counter("landscape_lock_handovers", "the lock taken by a session, or given "
                            "back (released, or its holder gone)", ["direction"],
                            registry=registry)
        self._subscription = None
        self._watcher: threading.Thread | None = None

    def rpc_timing(self, method: str, code: str, seconds: float) -> None:
        self.rpc.labels(method, code).observe(seconds)

    def time_planning(self, target, methods: tuple[str, ...]):
        """`target` with `methods` timed (kind: the method, or for `run` its job's name)."""
        return _Timed(target, methods, self.planning)

    def watch(self, bus) -> None:
        self._subscription = bus.subscribe()
        self._watcher = threading.Thread(target=self._count, name="metrics-events", daemon=True)
        self._watcher.start()

    def _count(self) -> None:
        for event in self._subscription:
            detail = event.detail
            if isinstance(detail, Alarm):
                self.alarms.labels(str(detail.code), detail.severity.name.lower()).inc()
            elif isinstance(detail, StateChange):
                was, now = detail.from_state in LOCKED, detail.to_state in LOCKED
                if was != now:
                    self.lock.labels("taken" if now else "released").inc()

    def close(self) -> None:
        if self._subscription is not None:
            self._subscription.close()
            self._watcher.join(5.0)


class _Timed:
    """Stands in for a planner: the named methods timed into a histogram, the rest as they
    are."""

    def __init__(self, target, methods: tuple[str, ...], histogram: Histogram):
        self._target, self._methods, self._histogram = target, methods, histogram

    def __getattr__(self, name: str):
        value = getattr(self._target, name)
        if name not in self._methods:
            return value

        def timed(*args, **kwargs):
            kind = args[0] if name == "run" and args and isinstance(args[0], str) else name
            started = time.perf_counter()
            try:
                return value(*args, **kwargs)
            finally:
                self._histogram.labels(kind).observe(time.perf_counter() - started)
        return timed
