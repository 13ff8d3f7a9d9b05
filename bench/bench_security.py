"""What the security layer costs a call, against the same server without it.

Prints, no pass/fail: round trips per second and p50/p99 latency of sequential unary calls
on one channel, for a read (GetDeviceState: role check, no audit) and a mutating call
(SetSpeed as the lock holder: role check, rate limit and an audit line), on four servers
started in this process one after the other (lock-step clock paced at real time):

- baseline: plaintext, no security layer installed (no tokens, audit or rate limit);
- tokens + audit + rate limit, plaintext;
- TLS + tokens + audit + rate limit;
- mutual TLS + tokens + audit + rate limit.

The client runs in a child process, as a supervisor would, so it does not share the
server's GIL. Run: .venv/bin/python bench/bench_security.py
"""
from __future__ import annotations

import argparse
import multiprocessing as mp
import statistics
import tempfile
import time
from pathlib import Path

from common import record

from landscape.cell.certs import make_certificates
from landscape.cell.tokens import make_tokens
from landscape.client import ClientTLS, Session, open_channel, read_token
from landscape.server.app import serve
from landscape.server.config import SecurityConfig, ServerConfig
from landscape.v1 import control_pb2, device_service_pb2_grpc, settings_pb2, types_pb2

CALLS = 800
WARMUP = 200


def _client(target, tls, token, out) -> None:
    with open_channel(target, tls, token) as channel, Session(channel, "bench") as session:
        session.lock()
        device = device_service_pb2_grpc.DeviceServiceStub(session.channel)
        figures = {}
        for name, call in (
                ("GetDeviceState", lambda: device.GetDeviceState(
                    control_pb2.GetDeviceStateRequest(), timeout=10)),
                ("SetSpeed", lambda: device.SetSpeed(
                    settings_pb2.SetSpeedRequest(
                    speed=50.0, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED), timeout=10))):
            for _ in range(WARMUP):
                call()
            times = []
            began = time.perf_counter()
            for _ in range(CALLS):
                start = time.perf_counter()
                call()
                times.append(time.perf_counter() - start)
            seconds = time.perf_counter() - began
            times.sort()
            figures[name] = (CALLS / seconds, statistics.median(times) * 1e3,
                             times[int(0.99 * len(times))] * 1e3)
        device.Release(control_pb2.ReleaseRequest(), timeout=10)
    out.put(figures)


def measure(security: SecurityConfig, tls: ClientTLS | None, token: str | None) -> dict:
    # Lock-step paced at real time: the simulated arm takes no more CPU than a real cycle.
    server = serve(ServerConfig(port=0, clock="lockstep", lockstep_pace=1.0, security=security))
    try:
        spawn = mp.get_context("spawn")
        out = spawn.Queue()
        child = spawn.Process(target=_client, args=(server.target, tls, token, out))
        child.start()
        figures = out.get(timeout=600)
        child.join(30)
        return figures
    finally:
        server.stop(grace=None)


def main() -> None:
    global CALLS
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer calls, for CI")
    if parser.parse_args().quick:
        CALLS = 150
    folder = Path(tempfile.mkdtemp(prefix="bench-security-"))
    certs = make_certificates(folder / "certs")
    token_files = make_tokens(folder / "tokens")
    operator = read_token(token_files["operator"])
    audit = dict(tokens=str(folder / "tokens"), audit_log=str(folder / "audit.log"),
                 rate_limit=1e6, rate_burst=1_000_000)
    tls = dict(tls_cert=str(certs.server_cert), tls_key=str(certs.server_key))
    client_pair = certs.clients["client"]
    runs = [
        ("baseline: no security layer", SecurityConfig(), None, None),
        ("tokens+audit+rate, plaintext", SecurityConfig(**audit), None, operator),
        ("TLS+tokens+audit+rate", SecurityConfig(**audit, **tls), ClientTLS(str(certs.ca)),
         operator),
        ("mTLS+tokens+audit+rate", SecurityConfig(**audit, **tls, mtls=True,
                                                  tls_ca=str(certs.ca)),
         ClientTLS(str(certs.ca), str(client_pair[0]), str(client_pair[1])), operator),
    ]
    print(f"{CALLS} sequential unary calls on one channel, client in its own process")
    baseline = {}
    for name, security, client_tls, token in runs:
        figures = measure(security, client_tls, token)
        for rpc, (rate, p50, p99) in figures.items():
            print(f"{name:<30} {rpc:<15} {rate:7.0f} calls/s   p50 {p50:.3f} ms   "
                  f"p99 {p99:.3f} ms")
            if not baseline.get(rpc):
                baseline[rpc] = p50
            else:
                record(f"{rpc} p50, {name.split(',')[0]}", p50, "ms", baseline=baseline[rpc],
                       baseline_name="no security layer")


if __name__ == "__main__":
    main()
