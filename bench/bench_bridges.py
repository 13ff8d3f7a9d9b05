"""What the bridges cost the cell (issue 29 item 4): cycle lateness p99 and GetRobotPosition
p50 with the Foxglove bridge, the OPC UA server and /metrics each serving a client, beside the
same with them off, in the same run.

One device server on the real-time clock (its 4 ms cycle process) in this process; a client
in a child process makes sequential GetRobotPosition calls while the cycle's own statistics
(shared memory) give its lateness. Then the same with /metrics on, the Foxglove bridge and the
OPC UA server running (each its own process, as `make run` starts them), and their clients in
another child: a Foxglove WebSocket client subscribed to every topic of the arm, an asyncua
client reading the six axis positions ten times a second, and a Prometheus scrape every
second (a scraper's usual interval is 15 s). Prints, no pass/fail.

Run: .venv/bin/python bench/bench_bridges.py [--quick]
"""
from __future__ import annotations

import argparse
import asyncio
import json
import multiprocessing as mp
import statistics
import subprocess
import sys
import time
import urllib.request

from common import collect, in_child, record

from landscape.server.app import serve
from landscape.server.config import ServerConfig
from landscape.v1 import device_service_pb2_grpc, settings_pb2


def _positions(target: str, calls: int) -> float:
    """p50 of `calls` sequential GetRobotPosition round trips, ms (after a warm-up)."""
    import grpc
    with grpc.insecure_channel(target) as channel:
        device = device_service_pb2_grpc.DeviceServiceStub(channel)
        times = []
        for i in range(calls + 200):
            start = time.perf_counter()
            device.GetRobotPosition(settings_pb2.GetRobotPositionRequest(), timeout=10)
            if i >= 200:
                times.append(time.perf_counter() - start)
    return statistics.median(times) * 1e3


async def _watchers(fox_port: int, opcua_url: str, metrics_url: str, stop) -> dict:
    """The bridges' clients until `stop` is set; how much each got."""
    import websockets
    from asyncua import Client
    counts = {"foxglove messages": 0, "opcua reads": 0, "scrapes": 0}

    async def foxglove():
        async with websockets.connect(f"ws://127.0.0.1:{fox_port}",
                                      subprotocols=["foxglove.sdk.v1"]) as ws:
            channels = []
            while not channels:
                message = json.loads(await ws.recv())
                if message["op"] == "advertise":
                    channels = message["channels"]
            await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
                {"id": i + 1, "channelId": c["id"]} for i, c in enumerate(channels)]}))
            while not stop.is_set():
                frame = await ws.recv()
                counts["foxglove messages"] += isinstance(frame, bytes)

    async def opcua():
        async with Client(opcua_url) as client:
            rob = await client.get_namespace_index("http://opcfoundation.org/UA/Robotics/")
            di = await client.get_namespace_index("http://opcfoundation.org/UA/DI/")
            own = await client.get_namespace_index("urn:landscape-grpc:cell")
            axes = await client.nodes.objects.get_child(
                [f"{di}:DeviceSet", f"{own}:cell", f"{rob}:MotionDevices", f"{own}:arm1",
                 f"{rob}:Axes"])
            nodes = [await a.get_child([f"{di}:ParameterSet", f"{rob}:ActualPosition"])
                     for a in await axes.get_children()]
            while not stop.is_set():
                await client.read_values(nodes)
                counts["opcua reads"] += 1
                await asyncio.sleep(0.1)

    async def prometheus():
        while not stop.is_set():
            await asyncio.to_thread(lambda: urllib.request.urlopen(metrics_url, timeout=10).read())
            counts["scrapes"] += 1
            await asyncio.sleep(1.0)

    tasks = [asyncio.create_task(job()) for job in (foxglove, opcua, prometheus)]
    while not stop.is_set():
        await asyncio.sleep(0.1)
        for task in tasks:
            if task.done():
                task.result()
    for task in tasks:
        task.cancel()
    return counts


def _start(module: str, target: str, ready: str) -> tuple[subprocess.Popen, str]:
    process = subprocess.Popen([sys.executable, "-m", module, "--device", f"arm1={target}",
                                "--port", "0"], stdout=subprocess.PIPE, text=True)
    for line in process.stdout:
        if line.startswith(ready):
            return process, line.split()[len(ready.split())]
    raise RuntimeError(f"{module} did not start")


def measure(calls: int, bridges: bool) -> tuple[float, float, dict]:
    """(cycle lateness p99 ms, GetRobotPosition p50 ms, what the watchers got)."""
    server = serve(ServerConfig(port=0, clock="realtime", metrics_port=0 if bridges else None))
    children, counts = [], {}
    try:
        if bridges:
            fox, fox_url = _start("landscape.bridges.foxglove", server.target, "Foxglove bridge on")
            ua, ua_url = _start("landscape.bridges.opcua", server.target, "OPC UA server on")
            children = [fox, ua]
            stop = mp.get_context("spawn").Event()
            watchers = in_child(_watchers, int(fox_url.rsplit(":", 1)[1]), ua_url,
                                server.metrics.url, stop)
            time.sleep(3.0)                       # every client connected and served
        server.link.clock.reset_stats()
        p50 = collect(in_child(_positions, server.target, calls), 600)
        late_p99 = server.link.stats().late_p99 * 1e3
        if bridges:
            stop.set()
            counts = collect(watchers, 60)
        return late_p99, p50, counts
    finally:
        for child in children:
            child.terminate()
            child.wait(20)
        server.stop(grace=None)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="fewer calls (CI)")
    calls = 2000 if parser.parse_args().quick else 15000
    off = measure(calls, bridges=False)
    on = measure(calls, bridges=True)
    print(f"{'':34} {'bridges off':>12} {'bridges on':>12}")
    print(f"{'cycle lateness p99 (ms)':34} {off[0]:12.3f} {on[0]:12.3f}")
    print(f"{'GetRobotPosition p50 (ms)':34} {off[1]:12.3f} {on[1]:12.3f}")
    print("served meanwhile: " + ", ".join(f"{n} {name}" for name, n in on[2].items()))
    record("bridges on: cycle lateness p99", on[0], "ms", baseline=off[0],
           baseline_name="bridges off, same run")
    record("bridges on: GetRobotPosition p50", on[1], "ms", baseline=off[1],
           baseline_name="bridges off, same run")


if __name__ == "__main__":
    main()
