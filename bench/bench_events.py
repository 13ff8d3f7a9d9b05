"""Event bus and EventService figures, against a bare gRPC stream of the same payload.

Prints, no pass/fail:
- the bus alone: microseconds per publish with no, draining and stalled subscribers;
- throughput: events per second through the bus and EventService.Subscribe to 1 and 20 gRPC
  subscribers without loss (the publisher keeps at most WINDOW events ahead of the slowest),
  against the same-run baseline of a bare server stream of the same message, no bus;
- end-to-end latency (publish -> client receive, p50/p99 in ms) at a steady PERIOD_S,
  against a bare server stream that stamps and sends on the same period;
- whether a stalled gRPC subscriber slows the publisher or a healthy subscriber.

The events are served by a real device server in this process (grpc.aio, its controller left
uninitialised so the cycle adds no noise; the bench publishes on its bus), the baseline by a
bare grpc.aio server beside it, so the difference is the bus and the servicer. The clients
run in a child process, as supervisors would, so they do not share the server's GIL.
Run: .venv/bin/python bench/bench_events.py
"""
from __future__ import annotations

import argparse
import asyncio
import math
import multiprocessing as mp
import statistics
import threading
import time

import grpc
from common import BareServer, record
from google.protobuf import wrappers_pb2

from landscape.server.events import bus as events
from landscape.server.app import serve
from landscape.server.config import ServerConfig
from landscape.server.api.convert import event_to_proto
from landscape.v1 import event_service_pb2 as pb
from landscape.v1 import event_service_pb2_grpc

N_EVENTS = 3_000         # per throughput run
WINDOW = 512             # events the publisher may run ahead of the slowest subscriber
N_LATENCY = 300          # samples per latency run
PERIOD_S = 0.01          # between latency samples: a busy device, 100 events/s
BUS_ONLY = 100_000       # publishes per bus-only run


def sample_event(bus: events.EventBus, i: int = 0) -> events.Event:
    """A typical event: a move's completion."""
    return bus.command(f"cmd-{i:06d}", "MoveAbsolute", events.Phase.DONE, "point_17")


# -- The baseline: a bare server stream of the same message, no bus --------------------------

def _sample_response() -> pb.SubscribeResponse:
    return pb.SubscribeResponse(event=event_to_proto(sample_event(events.EventBus())))


async def _burst(request: wrappers_pb2.UInt64Value, context):
    """Stream request.value copies of the sample as fast as the transport takes them."""
    response = _sample_response()
    for i in range(1, request.value + 1):
        response.event.sequence = i
        yield response


async def _tick(request: wrappers_pb2.UInt64Value, context):
    """Stream request.value samples, one per PERIOD_S, stamped with the instant it was due.

    Every stream wakes at the same instants (a grid of PERIOD_S), so 20 streams fan out each
    tick together, as the bus does with one event.
    """
    response = _sample_response()
    due = math.ceil(time.time() / PERIOD_S) * PERIOD_S
    for i in range(1, request.value + 1):
        due += PERIOD_S
        await asyncio.sleep(max(0.0, due - time.time()))
        response.event.sequence = i
        response.event.time.FromNanoseconds(round(due * 1e9))
        yield response


class Served:
    """The EventService of a device server (its bus), and the baseline streams on a bare
    grpc.aio server; both on loopback."""

    def __init__(self):
        self.device_server = serve(ServerConfig(port=0, clock="lockstep", start_device=False))
        self.bus = self.device_server.bus
        self.target = self.device_server.target
        self.baseline = _baseline()
        self.baseline_target = self.baseline.target

    def stop(self) -> None:
        self.baseline.stop()
        self.device_server.stop(grace=None)


def _baseline() -> BareServer:
    return BareServer("bench.Echo", {name: grpc.unary_stream_rpc_method_handler(
        fn, request_deserializer=wrappers_pb2.UInt64Value.FromString,
        response_serializer=pb.SubscribeResponse.SerializeToString)
        for name, fn in (("Burst", _burst), ("Tick", _tick))})


# -- Clients, in a child process -------------------------------------------------------------

def _open_stream(channel: grpc.aio.Channel, method: str, count: int):
    if method == "subscribe":
        return event_service_pb2_grpc.EventServiceStub(channel).Subscribe(pb.SubscribeRequest())
    call = channel.unary_stream(f"/bench.Echo/{method}",
                                request_serializer=wrappers_pb2.UInt64Value.SerializeToString,
                                response_deserializer=pb.SubscribeResponse.FromString)
    return call(wrappers_pb2.UInt64Value(value=count))


async def _client(target, method, last_sequence, index, progress, ready, options):
    """Read one stream until the event numbered last_sequence.

    Returns (first and last receive time in unix s, events received, events lost,
    latencies in ms).
    """
    latencies, lost, received, first = [], 0, 0, None
    async with grpc.aio.insecure_channel(target, options=options) as channel:
        stream = _open_stream(channel, method, last_sequence)
        ready.release()
        async for response in stream:
            now_ns = time.time_ns()
            first = first or now_ns / 1e9
            event = response.event
            if event.WhichOneof("detail") == "events_lost":
                lost += event.events_lost.last_sequence - event.events_lost.first_sequence + 1
            else:
                received += 1
                latencies.append((now_ns - event.time.ToNanoseconds()) / 1e6)
            progress[index] = event.sequence
            if event.sequence >= last_sequence:
                break
        stream.cancel()
    return first, time.time(), received, lost, latencies


def client_process(target, method, n_clients, last_sequence, progress, results, ready,
                   options=()):
    """n_clients streams on their own channels, on one asyncio loop (cheaper than threads)."""
    async def run():
        return await asyncio.gather(*(
            _client(target, method, last_sequence, i, progress, ready, list(options))
            for i in range(n_clients)))
    results.put(asyncio.run(run()))


class Clients:
    """n_clients streams in one child process; progress[i] is client i's last sequence."""

    def __init__(self, target, method, n_clients, last_sequence, first_sequence=1):
        ctx = mp.get_context("spawn")
        self.progress = ctx.Array("q", [first_sequence - 1] * n_clients, lock=False)
        self.results = ctx.Queue()
        ready = ctx.Semaphore(0)
        self.proc = ctx.Process(target=client_process, args=(
            target, method, n_clients, last_sequence, self.progress, self.results, ready),
            daemon=True)
        self.proc.start()
        for _ in range(n_clients):
            ready.acquire()

    def slowest(self) -> int:
        return min(self.progress)

    def collect(self):
        """Per client: (first receive, last receive, received, lost, latencies)."""
        out = self.results.get(timeout=300)
        self.proc.join(timeout=30)
        return out


def rate(results, n_events: int) -> float:
    """Events per second per subscriber, from the first receive to the last one."""
    return n_events / (max(r[1] for r in results) - min(r[0] for r in results))


# -- Runs ------------------------------------------------------------------------------------

def wait_subscribed(bus: events.EventBus, count: int, timeout: float = 60.0) -> None:
    """Until the bus has exactly `count` subscribers (clients come and go asynchronously)."""
    end = time.monotonic() + timeout
    while bus.subscriber_count != count:
        if time.monotonic() > end:
            raise RuntimeError(f"the bus has {bus.subscriber_count} subscribers, not {count}")
        time.sleep(0.005)


def bus_throughput(served: Served, n_clients: int, stalled: bool = False):
    """Through the bus to n_clients, the publisher staying within WINDOW of the slowest.

    Returns (events/s per subscriber, events the clients lost, mean us inside publish).
    stalled: add a client that subscribes and never reads (small HTTP/2 window).
    """
    bus, base, before = served.bus, served.bus.last_sequence, served.bus.subscriber_count
    if stalled:
        stalled_channel = grpc.insecure_channel(served.target,
                                                options=[("grpc.http2.bdp_probe", 0)])
        stalled_call = event_service_pb2_grpc.EventServiceStub(stalled_channel).Subscribe(
            pb.SubscribeRequest())
        wait_subscribed(bus, before + 1)
    clients = Clients(served.target, "subscribe", n_clients, base + N_EVENTS, base + 1)
    wait_subscribed(bus, before + n_clients + stalled)
    in_publish = 0.0
    for i in range(N_EVENTS):
        if i % 64 == 0:
            while base + i - clients.slowest() > WINDOW:
                time.sleep(0.0002)
        t = time.perf_counter()
        sample_event(bus, i)
        in_publish += time.perf_counter() - t
    results = clients.collect()
    if stalled:
        stalled_call.cancel()
        stalled_channel.close()
    wait_subscribed(bus, before)   # the next run counts from here
    return rate(results, N_EVENTS), sum(r[3] for r in results), in_publish / N_EVENTS * 1e6


def baseline_throughput(served: Served, n_clients: int) -> float:
    return rate(Clients(served.baseline_target, "Burst", n_clients, N_EVENTS).collect(),
                N_EVENTS)


def bus_latency(served: Served, n_clients: int) -> list[float]:
    bus, base, before = served.bus, served.bus.last_sequence, served.bus.subscriber_count
    clients = Clients(served.target, "subscribe", n_clients, base + N_LATENCY, base + 1)
    wait_subscribed(bus, before + n_clients)
    next_t = time.monotonic()
    for i in range(N_LATENCY):
        next_t += PERIOD_S
        time.sleep(max(0.0, next_t - time.monotonic()))
        sample_event(bus, i)
    results = clients.collect()
    wait_subscribed(bus, before)
    return [x for r in results for x in r[4]]


def baseline_latency(served: Served, n_clients: int) -> list[float]:
    return [x for r in Clients(served.baseline_target, "Tick", n_clients, N_LATENCY).collect()
            for x in r[4]]


def bus_only() -> dict[str, float]:
    """Microseconds per publish, in process, no gRPC."""
    figures = {}

    def timed(bus):
        start = time.perf_counter()
        for i in range(BUS_ONLY):
            sample_event(bus, i)
        return (time.perf_counter() - start) / BUS_ONLY * 1e6

    figures["no subscriber"] = timed(events.EventBus())
    bus = events.EventBus()
    with bus.subscribe():
        figures["1 stalled subscriber"] = timed(bus)
    bus = events.EventBus()
    subs = [bus.subscribe() for _ in range(20)]
    figures["20 stalled subscribers"] = timed(bus)
    for s in subs:
        s.close()
    bus = events.EventBus()
    sub = bus.subscribe()
    drained = threading.Thread(target=lambda: sum(1 for _ in sub))
    drained.start()
    figures["1 draining subscriber (thread)"] = timed(bus)
    sub.close()
    drained.join()
    return figures


def pct(values: list[float], q: float) -> float:
    return statistics.quantiles(values, n=100)[q - 1] if len(values) > 1 else float("nan")


def main() -> None:
    global N_EVENTS, N_LATENCY, BUS_ONLY
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer events, for CI")
    if parser.parse_args().quick:
        N_EVENTS, N_LATENCY, BUS_ONLY = 1_000, 200, 20_000
    served = Served()
    print(f"payload: one SubscribeResponse of {_sample_response().ByteSize()} bytes "
          f"(a command_done event)")
    try:
        print("\nbus alone (in process, no gRPC), microseconds per publish:")
        for name, us in bus_only().items():
            print(f"  {name:32s} {us:7.2f} us")
            record(f"event bus publish, {name}", us, "us")

        print(f"\nthroughput, {N_EVENTS} events, events/s per subscriber (no loss: the "
              f"publisher stays within {WINDOW} of the slowest):")
        for n in (1, 20):
            bus_rate, lost, publish_us = bus_throughput(served, n)
            base = baseline_throughput(served, n)
            print(f"  {n:2d} subscriber(s): bus {bus_rate:7.0f}/s (lost {lost}, publish "
                  f"{publish_us:5.1f} us)   bare stream {base:7.0f}/s   "
                  f"ratio {bus_rate / base:4.2f}")
            record(f"events/s per subscriber, {n} subscriber(s)", bus_rate, "events/s",
                   baseline=base, baseline_name="bare stream", better="higher")
        bus_rate, lost, publish_us = bus_throughput(served, 1, stalled=True)
        print(f"   1 subscriber + 1 stalled client: bus {bus_rate:7.0f}/s (lost {lost}, "
              f"publish {publish_us:5.1f} us)")

        print(f"\nlatency publish -> client receive, {N_LATENCY} events at "
              f"{1 / PERIOD_S:.0f}/s, ms p50 / p99:")
        for n in (1, 20):
            lat, base = bus_latency(served, n), baseline_latency(served, n)
            print(f"  {n:2d} subscriber(s): bus {pct(lat, 50):6.3f} / {pct(lat, 99):6.3f}   "
                  f"bare stream {pct(base, 50):6.3f} / {pct(base, 99):6.3f}")
            record(f"publish to receive p99, {n} subscriber(s) at 100 ev/s", pct(lat, 99), "ms",
                   baseline=pct(base, 99), baseline_name="bare stream")
    finally:
        served.stop()


if __name__ == "__main__":
    main()
