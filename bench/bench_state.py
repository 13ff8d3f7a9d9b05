"""Live state and watchers (issue 12), each beside a baseline measured in the same run. Prints
figures, no pass/fail. Command to motion (send -> first moving cycle) is bench_motion_start's.

- State fan-out: 50 StateService.StreamState subscribers at 250 Hz while a path runs: samples
  per second per subscriber, gaps, p99 sample age (receive - the cycle's time), cycle overruns
  and the server's CPU; baseline: a bare grpc.aio server streaming a message of the same size
  every 4 ms to 50 subscribers.
- 1,000 idle event subscribers: the server's resident memory, and the unary call latency
  (GetDeviceState) beside them, against the latency with none.
- Event latency: tag events of a path from the cycle that passed the tag to 1 and 50
  subscribers, p50/p99, and the server loop's CPU per event and subscriber; baseline: a bare
  grpc.aio stream of the same events (the device round's, stamped anew, same spacing).

The device server runs here on the real-time clock (its cycle process apart); every client runs
in a child process, as supervisors would. Run: .venv/bin/python bench/bench_state.py [--quick]
[--only events ...]
"""
from __future__ import annotations

import argparse
import asyncio
import dataclasses
import functools
import math
import multiprocessing as mp
import os
import statistics
import threading
import time

import grpc
from common import BareServer, collect, in_child, pct, record
from google.protobuf import wrappers_pb2

from landscape.server.api.convert import event_to_proto
from landscape.server.app import serve
from landscape.server.config import ServerConfig
from landscape.server.api.stream_caps import DEFAULT_CAPS, Cap
from landscape.server.device.states import State
from landscape.v1 import (control_pb2, device_service_pb2_grpc, event_service_pb2,
                          event_service_pb2_grpc, motion_pb2, state_service_pb2,
                          state_service_pb2_grpc, types_pb2)

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
HOME = [0.0, 0.0, 1.5708, 0.0, 1.5708, 0.0]
OWN_CONNECTION = [("grpc.use_local_subchannel_pool", 1)]
# The grpc.aio options the device server runs with (app.py), for the bare servers beside it.
DEVICE_SERVER_OPTIONS = [("grpc.max_receive_message_length", ServerConfig().max_message_bytes),
                         ("grpc.so_reuseport", 0)]
TAGS = 50   # of the holder's path: the event latency's events per round


def rss_mb(pid: int | None = None) -> float:
    with open(f"/proc/{pid or os.getpid()}/status") as status:
        kb = next(int(line.split()[1]) for line in status if line.startswith("VmRSS"))
    return kb / 1024


# -- the baseline server: bare grpc.aio, in this process like the device server ----------------

def _sample_size_message() -> state_service_pb2.StreamStateResponse:
    sample = state_service_pb2.StateSample(
        sequence=123456, controller_time=493.824, joint_positions=[0.1] * 6,
        joint_velocities=[0.2] * 6, commanded_positions=[0.1] * 6, joint_torques=[1.5] * 6,
        tool_pose=types_pb2.Pose(x=0.5, y=0.1, z=0.6, roll=3.1, pitch=0.01, yaw=0.2),
        device_state=types_pb2.DEVICE_STATE_MOVING, motion_control_state="running_trajectory",
        control_mode="power_on", command_id="PathMove-17", point_name="ring", tag_name="t7",
        units=types_pb2.Units(linear=types_pb2.LINEAR_UNIT_METERS,
                              angular=types_pb2.ANGULAR_UNIT_RADIANS))
    return state_service_pb2.StreamStateResponse(sample=sample)


async def _ticking(request: wrappers_pb2.UInt64Value, context):
    """Every 4 ms (on one grid for every stream) a message of a state sample's size, stamped."""
    message = _sample_size_message()
    due = math.ceil(time.time() / 0.004) * 0.004
    for i in range(request.value):
        due += 0.004
        await asyncio.sleep(max(0.0, due - time.time()))
        message.sample.sequence = i
        message.sample.time.FromNanoseconds(round(due * 1e9))
        yield message


class BareEvents:
    """The event latency's baseline: the bus's work done bare. A thread (as the link's is for
    the device) publishes the events of the device's round before it, stamped anew, at their
    spacing, and wakes every waiting stream with one hand-over to the server's loop; each
    stream then sends it as a plain grpc.aio stream does (a message per stream, serialized
    by grpc). The same events (the path's tags and the command's and state's events around
    them: a baseline of tags alone sent 50 messages to the device's 54), the same streams, the
    same clients."""

    def __init__(self):
        self.loop: asyncio.AbstractEventLoop | None = None   # the bare server's (BareServer)
        self.streams = 0
        self._sent: list[event_service_pb2.SubscribeResponse] = []
        self._waiting: list[asyncio.Future] = []   # one per waiting stream, as the bus has

    async def stream(self, request, context):
        self.streams += 1
        try:
            i = len(self._sent)
            while True:
                while i >= len(self._sent):
                    waiter = asyncio.get_running_loop().create_future()
                    self._waiting.append(waiter)
                    await waiter
                yield self._sent[i]
                i += 1
        finally:
            self.streams -= 1

    def publish(self, events: list) -> None:
        """`events` (the bus's records) again, as far apart as they were (call from a thread)."""
        start = time.time()
        for event in events:
            time.sleep(max(0.0, start + event.time - events[0].time - time.time()))
            event = dataclasses.replace(event, time=time.time())
            self.loop.call_soon_threadsafe(self._deliver, event_service_pb2.SubscribeResponse(
                event=event_to_proto(event)))

    def _deliver(self, message) -> None:
        self._sent.append(message)
        waiting, self._waiting = self._waiting, []
        for waiter in waiting:
            if not waiter.done():   # else its stream was cancelled
                waiter.set_result(None)


async def _echo(request: wrappers_pb2.UInt64Value, context):
    return request


def bare_server(events: BareEvents) -> BareServer:
    server = BareServer("bench.Bare", {
        "Events": grpc.unary_stream_rpc_method_handler(
            events.stream, request_deserializer=wrappers_pb2.UInt64Value.FromString,
            response_serializer=event_service_pb2.SubscribeResponse.SerializeToString),
        "Tick": grpc.unary_stream_rpc_method_handler(
            _ticking, request_deserializer=wrappers_pb2.UInt64Value.FromString,
            response_serializer=state_service_pb2.StreamStateResponse.SerializeToString),
        "Echo": grpc.unary_unary_rpc_method_handler(
            _echo, request_deserializer=wrappers_pb2.UInt64Value.FromString,
            response_serializer=wrappers_pb2.UInt64Value.SerializeToString)},
        options=DEVICE_SERVER_OPTIONS)
    events.loop = server.loop
    return server


# -- children ----------------------------------------------------------------------------------

async def watchers(target: str, n: int, seconds: float, bare: bool):
    """n streams read for `seconds`: per stream (count, gaps, ages in ms)."""
    async def one(channel):
        if bare:
            call = channel.unary_stream(
                "/bench.Bare/Tick", request_serializer=wrappers_pb2.UInt64Value.SerializeToString,
                response_deserializer=state_service_pb2.StreamStateResponse.FromString)(
                wrappers_pb2.UInt64Value(value=int(seconds * 300)))
        else:
            call = state_service_pb2_grpc.StateServiceStub(channel).StreamState(
                state_service_pb2.StreamStateRequest(rate_hz=250))
        count, gaps, ages, last = 0, 0, [], None
        end = time.time() + seconds
        async for message in call:
            if message.WhichOneof("message") != "sample":
                continue
            now = time.time()
            sample = message.sample
            ages.append((now - sample.time.ToNanoseconds() / 1e9) * 1000)
            if last is not None and sample.sequence != last + 1:
                gaps += 1
            last, count = sample.sequence, count + 1
            if now > end:
                break
        call.cancel()
        return count, gaps, ages

    channel = grpc.aio.insecure_channel(target, options=OWN_CONNECTION)
    try:
        return await asyncio.gather(*(one(channel) for _ in range(n)))
    finally:
        await channel.close()


async def idle_subscribers(target: str, n: int, hold: float, ready):
    """n event subscriptions on n // 50 connections, held idle for `hold` s."""
    channels = [grpc.aio.insecure_channel(target, options=OWN_CONNECTION)
                for _ in range(max(1, n // 50))]
    calls = [event_service_pb2_grpc.EventServiceStub(channels[i % len(channels)]).Subscribe(
        event_service_pb2.SubscribeRequest()) for i in range(n)]
    await asyncio.gather(*(c.wait_for_connection() for c in calls))
    ready.set()
    await asyncio.sleep(hold)
    for call in calls:
        call.cancel()
    for channel in channels:
        await channel.close()
    return n


async def unary_latency(target: str, n: int, bare: bool):
    async with grpc.aio.insecure_channel(target) as channel:
        if bare:
            call = channel.unary_unary(
                "/bench.Bare/Echo", request_serializer=wrappers_pb2.UInt64Value.SerializeToString,
                response_deserializer=wrappers_pb2.UInt64Value.FromString)
            request = wrappers_pb2.UInt64Value(value=1)
        else:
            call = device_service_pb2_grpc.DeviceServiceStub(channel).GetDeviceState
            request = control_pb2.GetDeviceStateRequest()
        out = []
        for _ in range(n):
            began = time.perf_counter()
            await call(request)
            out.append((time.perf_counter() - began) * 1000)
        return out


async def event_watchers(target: str, n: int, bare: bool, last: str):
    """n event streams until the tag named `last`: per stream, (sequence, receive time, the
    event's own time) per tag event. The bare server's streams carry tag events too."""
    async def one(channel):
        got = []
        if bare:
            call = channel.unary_stream(
                "/bench.Bare/Events", request_serializer=wrappers_pb2.UInt64Value.SerializeToString,
                response_deserializer=event_service_pb2.SubscribeResponse.FromString)(
                wrappers_pb2.UInt64Value())
        else:
            call = event_service_pb2_grpc.EventServiceStub(channel).Subscribe(
                event_service_pb2.SubscribeRequest())
        async for reply in call:
            event = reply.event
            if event.event_id == "tag_reached":
                got.append((event.sequence, time.time(), event.time.ToNanoseconds() / 1e9))
                if event.command.tag_name == last:
                    break
        call.cancel()
        return got

    channel = grpc.aio.insecure_channel(target, options=OWN_CONNECTION)
    try:
        return await asyncio.gather(*(one(channel) for _ in range(n)))
    finally:
        await channel.close()


# -- sections ------------------------------------------------------------------------------------

class Holder:
    """The lock holder in this process: runs a long blended ring path while others watch."""

    def __init__(self, server):
        self.server = server
        self._take()
        header = motion_pb2.PathHeader(path_name="tags", frame=JOINT,
                                       motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                       offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)
        tags = [types_pb2.TagStruct(
            joint_values=[0.4 * math.sin(2 * math.pi * i / TAGS), 0.1 * math.cos(2 * math.pi * i / TAGS),
                          1.5708, 0.0, 1.5708, 0.0], tag_name=f"t{i}", transition_speed=30)
            for i in range(TAGS)]
        try:
            self.device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header, tags=tags)]),
                                 timeout=60)
        except grpc.RpcError:
            pass

    def _take(self):
        from landscape.client import Session
        self.session = Session(grpc.insecure_channel(self.server.target), "holder").open()
        self.session.lock()
        self.device = device_service_pb2_grpc.DeviceServiceStub(self.session.channel)
        self.device.Activate(control_pb2.ActivateRequest(), timeout=10)

    def run(self, cycles: int):
        """Run the path `cycles` times, once the device rests (the path's last tag comes
        before the arm has settled at its end); locked again if the session was lost (a
        machine at load 14 can hold its keep-alives back for the device's 2 s)."""
        end = time.monotonic() + 30
        while self.server.device.state is not State.RESTING and time.monotonic() < end:
            if self.server.device.state is State.UNLOCKED:
                print("  (the holder's session was lost: locked again)")
                self.session.close()
                self._take()
            time.sleep(0.02)
        return self.device.PathMove(motion_pb2.PathMoveRequest(path_name="tags",
                                                               number_of_cycles=cycles))

    def stop(self):
        """Stop and drop the path; returns once the device rests (a server loaded by 50
        watchers may answer a call after its deadline: asked again)."""
        device, end = self.server.device, time.monotonic() + 60
        while device.state is not State.RESTING:
            if time.monotonic() > end:
                raise RuntimeError(f"the holder's path did not stop: the device is "
                                   f"{device.state.value}, locked by "
                                   f"{device.status().lock_holder or 'nobody'}")
            for call, request in ((self.device.StopMotion, motion_pb2.StopMotionRequest()),
                                  (self.device.AbortMotion, motion_pb2.AbortMotionRequest())):
                try:
                    call(request, timeout=10)
                except grpc.RpcError:
                    pass   # ended already, or answered late: the state says
            time.sleep(0.05)

    def close(self):
        self.session.close()


def fan_out(server, bare: BareServer, holder: Holder, seconds: float):
    print(f"\nstate fan-out: 50 subscribers at 250 Hz for {seconds:g} s (5 processes x 10)")
    for label, target, is_bare in (("device server", server.target, False),
                                   ("bare stream", bare.target, True)):
        if not is_bare:
            holder.run(cycles=1000)
        before, cpu0 = server.link.stats(), time.process_time()
        children = [in_child(watchers, target, 10, seconds, is_bare) for _ in range(5)]
        results = [r for _, q in children for r in q.get(timeout=seconds + 120)]
        cpu = (time.process_time() - cpu0) / seconds * 100
        after = server.link.stats()
        if not is_bare:
            holder.stop()
        rates = [c / seconds for c, _, _ in results]
        ages = [a for _, _, ages in results for a in ages]
        gaps = sum(g for _, g, _ in results)
        print(f"  {label:13s}: {statistics.mean(rates):6.1f} samples/s per subscriber "
              f"(min {min(rates):5.1f}), gaps {gaps}, age p50 {pct(ages, 50):6.2f} ms "
              f"p99 {pct(ages, 99):7.2f} ms, this process's CPU {cpu:5.1f} %, cycle overruns "
              f"{after.overruns - before.overruns}, late p99 {after.late_p99 * 1e3:.3f} ms")
        if is_bare:
            record("state fan-out 50 x 250 Hz, samples/s per subscriber", device_rate,
                   "samples/s", baseline=statistics.mean(rates), baseline_name="bare stream",
                   better="higher")
            record("state fan-out 50 x 250 Hz, sample age p99", device_age, "ms",
                   baseline=pct(ages, 99), baseline_name="bare stream")
        else:
            device_rate, device_age = statistics.mean(rates), pct(ages, 99)
            record("cycle overruns, 50 state subscribers", after.overruns - before.overruns,
                   "cycles", goal=0)


def idle(server, bare: BareServer, n: int):
    print(f"\n{n} idle event subscribers:")
    quiet = unary_latency_in_child(server.target, False)
    rss0 = rss_mb()
    ctx = mp.get_context("spawn")
    ready = ctx.Event()
    proc, queue = in_child(idle_subscribers, server.target, n, 20.0, ready)
    ready.wait(120)
    time.sleep(1.0)
    rss1 = rss_mb()
    busy = unary_latency_in_child(server.target, False)
    echo = unary_latency_in_child(bare.target, True)
    queue.get(timeout=120)
    record(f"server memory, {n} idle subscribers", rss1, "MB", baseline=rss0,
           baseline_name="none")
    record(f"GetDeviceState p50 beside {n} idle subscribers", pct(busy, 50), "ms",
           baseline=pct(quiet, 50), baseline_name="none", goal=1.5 * pct(quiet, 50))
    print(f"  server memory {rss0:.0f} MB -> {rss1:.0f} MB with them "
          f"({(rss1 - rss0) * 1024 / n:.1f} kB each)")
    print(f"  GetDeviceState p50/p99: {pct(quiet, 50):.3f} / {pct(quiet, 99):.3f} ms alone, "
          f"{pct(busy, 50):.3f} / {pct(busy, 99):.3f} ms beside them "
          f"(x{pct(busy, 50) / pct(quiet, 50):.2f}); bare echo {pct(echo, 50):.3f} / "
          f"{pct(echo, 99):.3f} ms")


def unary_latency_in_child(target: str, is_bare: bool, n: int = 2000):
    _, queue = in_child(unary_latency, target, n, is_bare)
    return queue.get(timeout=300)


def event_latency(server, bare: BareServer, events: BareEvents, holder: Holder, rounds: int):
    """Rounds alternate device, bare, device, ...: the figures are the medians of the rounds'
    percentiles, so a busy moment of the shared machine spoils one round, not one side."""
    print(f"\nevent latency, a tag's cycle (bare: its stamp) -> a subscriber receives it, ms; "
          f"medians of {rounds} alternating rounds:")
    motions = server.device.motions
    cycle_of: dict[int, float] = {}
    original = motions.on_report
    device_cpu, bare_cpu = loop_cpu(server.runner.loop), loop_cpu(bare.loop)

    def on_report(msg):   # which cycle each tag event comes from (the executor stamps it)
        original(msg)
        if msg.get("op") == "mark":
            cycle_of[server.bus.last_sequence] = msg["wall_time"]
    motions.on_report = on_report
    try:
        for n in (1, 50):
            device, published, base, cpu = [], [], [], {"device": [], "bare": []}
            for _ in range(rounds):
                first = server.bus.last_sequence + 1
                got, used = _event_round(n, server.target, False,
                                         lambda: server.bus.subscriber_count,
                                         lambda: holder.run(1), device_cpu)
                cpu["device"].append(used)
                device.append([(t - cycle_of[s]) * 1000 for s, t, _ in got if s in cycle_of])
                published.append([(t - stamp) * 1000 for _, t, stamp in got])
                round_events = _round_events(server, first)
                got, used = _event_round(n, bare.target, True, lambda: events.streams,
                                         functools.partial(events.publish, round_events),
                                         bare_cpu)
                cpu["bare"].append(used)
                base.append([(t - stamp) * 1000 for _, t, stamp in got])
                time.sleep(1.0)
            figures = {name: [statistics.median(pct(r, q) for r in runs) for q in (50, 99)]
                       for name, runs in (("device", device), ("published", published),
                                          ("bare", base))}
            (p50, p99), (pub50, pub99), (b50, b99) = figures.values()
            print(f"  {n:2d} subscriber(s): p50 {p50:6.2f} p99 {p99:6.2f} (from the bus: "
                  f"{pub50:5.2f} / {pub99:5.2f})   bare stream p50 {b50:6.2f} p99 {b99:6.2f}"
                  f"   x{p99 / b99:.2f} at p99; rounds' p99: "
                  f"{' '.join(f'{pct(d, 99):.1f}/{pct(b, 99):.1f}' for d, b in zip(device, base))}")
            loop_us = {side: statistics.median(used) for side, used in cpu.items()}
            print(f"      the server loop's CPU per event and subscriber: {loop_us['device']:.0f} "
                  f"us, bare {loop_us['bare']:.0f} us (x{loop_us['device'] / loop_us['bare']:.2f})")
            record(f"event fan-out, loop CPU per event and subscriber, {n} subscriber(s)",
                   loop_us["device"], "us", baseline=loop_us["bare"],
                   baseline_name="bare event stream")
            record(f"event latency p99, {n} subscriber(s)", p99, "ms", baseline=b99,
                   baseline_name="bare event stream", goal=1.2 * b99)
    finally:
        motions.on_report = original


def _round_events(server, first: int) -> list:
    """The events the device published from sequence `first` to the end of its path (it
    rests), which its streams sent; the bus keeps them (its history)."""
    end = time.monotonic() + 30
    while server.device.state is not State.RESTING and time.monotonic() < end:
        time.sleep(0.02)
    return [server.bus.kept(s) for s in range(first, server.bus.last_sequence + 1)]


def _event_round(n: int, target: str, bare: bool, subscribed, publish,
                 loop_cpu) -> tuple[list[tuple], float]:
    """n subscribers (10 to a child process) until the last tag; `publish()` once they all
    listen. Every subscriber's (sequence, receive time, the event's time) of every tag, and
    the server loop's CPU time per tag and subscriber, us (the machine's load barely moves
    it, unlike the latencies)."""
    before = subscribed()
    children = [in_child(event_watchers, target, min(n, 10), bare, f"t{TAGS - 1}")
                for _ in range(max(1, n // 10))]
    deadline = time.monotonic() + 120
    while subscribed() < before + n and time.monotonic() < deadline:
        time.sleep(0.05)
    cpu = loop_cpu()
    publish()
    got = [tag for child in children for stream in collect(child, 300) for tag in stream]
    return got, (loop_cpu() - cpu) / len(got) * 1e6


def loop_cpu(loop: asyncio.AbstractEventLoop):
    """A function giving the CPU seconds used so far by the thread that runs `loop`."""
    async def ident():
        return threading.get_ident()
    clock = time.pthread_getcpuclockid(asyncio.run_coroutine_threadsafe(ident(), loop).result())
    return lambda: time.clock_gettime(clock)


SECTIONS = ["fan-out", "events", "idle"]


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="shorter runs, for CI")
    parser.add_argument("--only", nargs="+", choices=SECTIONS, default=SECTIONS,
                        help="run these sections only (default: all)")
    args = parser.parse_args()
    # Every watcher here comes from this machine's address: one client to the stream caps,
    # whose per-client share (limits.DEFAULT_CAPS) is for a cell's supervisors, not 1,000.
    caps = {**DEFAULT_CAPS, "watch": Cap(per_client=2_000, total=20_000)}
    server = serve(ServerConfig(port=0, clock="realtime", stream_caps=caps))
    events = BareEvents()
    bare = bare_server(events)
    holder = Holder(server)
    try:
        print(f"state sample message: {_sample_size_message().ByteSize()} bytes; real-time "
              f"priority: {'no: ' + '; '.join(server.link.tuning_problems) if server.link.tuning_problems else 'yes'}")
        if "fan-out" in args.only:
            fan_out(server, bare, holder, 3.0 if args.quick else 6.0)
        if "events" in args.only:
            event_latency(server, bare, events, holder, 3 if args.quick else 5)
        holder.device.Deactivate(control_pb2.DeactivateRequest(), timeout=10)
        holder.close()
        if "idle" in args.only:
            idle(server, bare, 200 if args.quick else 1000)
    finally:
        bare.stop()
        server.stop(grace=None)


if __name__ == "__main__":
    main()
