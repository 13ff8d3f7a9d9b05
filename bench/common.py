"""What the benchmarks share: a bare grpc.aio server to measure against, children to run
clients in (so they do not share the server's interpreter), and percentiles."""
from __future__ import annotations

import asyncio
import inspect
import json
import math
import multiprocessing as mp
import os
import threading
import time
from queue import Empty

import grpc
import numpy as np


def pct(values, q: float) -> float:
    return float(np.percentile(values, q)) if len(values) else math.nan


# The report runner (report.py) names a file here; a bench run alone records nothing.
REPORT_ENV = "LANDSCAPE_BENCH_JSON"


def record(figure: str, value: float, unit: str, *, baseline: float | None = None,
           baseline_name: str = "", goal: float | None = None, better: str = "lower",
           points: list | None = None) -> None:
    """One figure for the report, beside what a bench prints: its same-run baseline and the
    goal an issue names (met when the value is at most, or with better="higher" at least,
    the goal); points: rows of numbers behind it, for the report's plot (report.py --plot)."""
    path = os.environ.get(REPORT_ENV)
    if not path:
        return
    row = {"figure": figure, "value": value, "unit": unit, "baseline": baseline,
           "baseline_name": baseline_name, "goal": goal, "better": better,
           **({"points": points} if points is not None else {})}
    with open(path, "a") as out:
        out.write(json.dumps(row) + "\n")


def skipped(reason: str) -> None:
    """The bench could not run here (a tool is missing): the report says why."""
    record("skipped", math.nan, "", baseline_name=reason)


class BareServer:
    """A bare grpc.aio server on a loop thread of this process, like the device server's:
    `handlers` maps method names of service `service` to grpc method handlers; `options`:
    the grpc.aio server's channel options."""

    def __init__(self, service: str, handlers: dict, options=()):
        self.loop = asyncio.new_event_loop()
        threading.Thread(target=self.loop.run_forever, daemon=True).start()
        self.server, port = asyncio.run_coroutine_threadsafe(
            self._start(service, handlers, options), self.loop).result()
        self.target = f"127.0.0.1:{port}"

    async def _start(self, service: str, handlers: dict, options):
        server = grpc.aio.server(options=options)
        server.add_generic_rpc_handlers((grpc.method_handlers_generic_handler(service,
                                                                             handlers),))
        port = server.add_insecure_port("127.0.0.1:0")
        await server.start()
        return server, port

    def stop(self) -> None:
        asyncio.run_coroutine_threadsafe(self.server.stop(None), self.loop).result()
        self.loop.call_soon_threadsafe(self.loop.stop)


def in_child(func, *args):
    """Run func(*args) (a coroutine function, or a plain one) in a spawned child; returns
    (process, queue) — the queue gets the result. Keep both until the child has started."""
    ctx = mp.get_context("spawn")
    queue = ctx.Queue()
    proc = ctx.Process(target=_child_main, args=(queue, func, args), daemon=True)
    proc.start()
    return proc, queue


def collect(child, timeout: float):
    """The result of an in_child (process, queue): waits up to `timeout` s, and fails at once,
    saying so, when the child exits without one (its traceback is on stderr above)."""
    process, queue = child
    end = time.monotonic() + timeout
    while True:
        try:
            return queue.get(timeout=1.0)
        except Empty:
            if not process.is_alive():
                raise RuntimeError(f"a child exited (code {process.exitcode}) with no result; "
                                   f"its error is above") from None
            if time.monotonic() > end:
                raise TimeoutError(f"a child gave no result within {timeout:g} s") from None


def _child_main(queue, func, args):
    result = func(*args)
    queue.put(asyncio.run(result) if inspect.iscoroutine(result) else result)
