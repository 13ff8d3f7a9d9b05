"""CRCL gateway figures, against a bare TCP echo of the same documents in the same run.

Prints, no pass/fail:
- commands per second for a 1,000-command program sent as NIST's client does (one command,
  then GetStatus polls until it is Done), with every command's status checked;
- GetStatus round trip p50/p99 (ms) with a CRCL session open;
- the baseline: a bare asyncio TCP echo server that returns each document as it comes, driven
  by the same client code (send, read until the closing tag), for both figures.

The device server (`python -m landscape.server`, real-time clock) and the gateway
(`python -m landscape.gateway`) run in their own processes as users start them; the client
runs here. The program's commands are settings and zero dwells, so the figures measure the
gateway, not the arm's travel time. Where a command's time goes (cProfile of the gateway under
this bench): settings are carried out at once and are Done at the first poll, and speeds reach
the device only before a motion, so no command here calls the device; per command the gateway
splits and parses two documents (about 15 and 12 us: wire, hardened parse, schema, typed
parser) and builds one status (about 15 us: a sample's joints and pose are made into XML once);
the rest is the two TCP round trips and the scheduling of three processes.
Run: .venv/bin/python bench/bench_crcl.py
"""
from __future__ import annotations

import asyncio
import multiprocessing as mp
import re
import socket
import statistics
import subprocess
import sys
import time
from pathlib import Path

from common import record  # noqa: E402  (bench/ is the script's folder)

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))
from support import spawned_server  # noqa: E402

N_COMMANDS = 1_000
N_STATUS = 2_000
XSI = 'xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance"'
COMMANDS = [
    ("SetEndPoseTolerance", "<Tolerance><XPointTolerance>0.001</XPointTolerance></Tolerance>"),
    ("ConfigureJointReports", "<ResetAll>false</ResetAll><ConfigureJointReport><JointNumber>1"
                              "</JointNumber><ReportPosition>true</ReportPosition>"
                              "<ReportTorqueOrForce>false</ReportTorqueOrForce><ReportVelocity>"
                              "true</ReportVelocity></ConfigureJointReport>"),
    ("Dwell", "<DwellTime>0</DwellTime>"),
    ("SetMotionCoordination", "<Coordinated>true</Coordinated>"),
    ("SetTransSpeed", '<TransSpeed xsi:type="TransSpeedRelativeType"><Fraction>0.3</Fraction>'
                      "</TransSpeed>"),
    ("SetTransSpeed", '<TransSpeed xsi:type="TransSpeedRelativeType"><Fraction>0.4</Fraction>'
                      "</TransSpeed>"),
    ("SetLengthUnits", "<UnitName>meter</UnitName>"),
]


def document(kind: str, command_id: int, body: str = "") -> bytes:
    return (f'<?xml version="1.0" encoding="UTF-8"?><CRCLCommandInstance {XSI}><CRCLCommand '
            f'xsi:type="{kind}Type"><CommandID>{command_id}</CommandID>{body}</CRCLCommand>'
            f"</CRCLCommandInstance>").encode()


class Client:
    """Send a document, read one reply document (found by its closing tag)."""

    def __init__(self, port: int, end: bytes):
        self.sock = socket.create_connection(("127.0.0.1", port))
        self.sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.end, self.buffer = end, b""

    def ask(self, data: bytes) -> bytes:
        self.sock.sendall(data)
        while (i := self.buffer.find(self.end)) < 0:
            chunk = self.sock.recv(65536)
            if not chunk:
                raise ConnectionError("closed")
            self.buffer += chunk
        i += len(self.end)
        reply, self.buffer = self.buffer[:i], self.buffer[i:]
        return reply

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)


def _state(status: bytes) -> tuple[str, str]:
    return (re.search(rb"<CommandID>(\d+)</CommandID>", status).group(1).decode(),
            re.search(rb"<CommandState>(\w+)</CommandState>", status).group(1).decode())


def run_program(client: Client, echo: bool) -> tuple[float, int]:
    """(seconds for N_COMMANDS commands, GetStatus polls used)."""
    polls = 0
    start = time.perf_counter()
    for i in range(N_COMMANDS):
        kind, body = COMMANDS[i % len(COMMANDS)]
        command_id = 10 + i
        if echo:   # the echo answers each document: a command, then one GetStatus
            client.ask(document(kind, command_id, body))
            client.ask(document("GetStatus", command_id))
            polls += 1
            continue
        client.send(document(kind, command_id, body))
        while True:
            polls += 1
            status = client.ask(document("GetStatus", command_id))
            got_id, state = _state(status)
            if got_id == str(command_id) and state in ("CRCL_Done", "CRCL_Error"):
                if state == "CRCL_Error":
                    raise RuntimeError(status.decode())
                break
    return time.perf_counter() - start, polls


def status_round_trips(client: Client) -> list[float]:
    times = []
    get = document("GetStatus", 5)
    for _ in range(N_STATUS):
        start = time.perf_counter()
        client.ask(get)
        times.append((time.perf_counter() - start) * 1e3)
    return times


def _percentile(values: list[float], q: float) -> float:
    return statistics.quantiles(values, n=100)[q - 1]


async def _echo(reader, writer):
    while data := await reader.read(65536):
        writer.write(data)
        await writer.drain()
    writer.close()


def _echo_server(port_queue) -> None:
    async def main():
        server = await asyncio.start_server(_echo, "127.0.0.1", 0)
        port_queue.put(server.sockets[0].getsockname()[1])
        await server.serve_forever()
    asyncio.run(main())


def measure(client: Client, echo: bool) -> tuple[float, int, list[float]]:
    if not echo:
        client.send(document("InitCanon", 1))
        while _state(client.ask(document("GetStatus", 1))) != ("1", "CRCL_Done"):
            time.sleep(0.01)
    seconds, polls = run_program(client, echo)
    return seconds, polls, status_round_trips(client)


def report(name: str, seconds: float, polls: int, rtt: list[float]) -> None:
    print(f"{name:<26} {N_COMMANDS / seconds:8.0f} commands/s  ({polls / N_COMMANDS:.2f} "
          f"GetStatus per command)   GetStatus p50 {_percentile(rtt, 50):.3f} ms  "
          f"p99 {_percentile(rtt, 99):.3f} ms")


def main() -> None:
    ports: mp.Queue = mp.Queue()
    echo = mp.Process(target=_echo_server, args=(ports,), daemon=True)
    echo.start()
    baseline = measure(Client(ports.get(timeout=10), b"</CRCLCommandInstance>"), echo=True)
    echo.terminate()
    with spawned_server() as target:
        gateway = subprocess.Popen(
            [sys.executable, "-m", "landscape.gateway", "--device", target, "--port", "0"],
            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
        try:
            for line in gateway.stdout:
                if "CRCL gateway listening on" in line:
                    port = int(line.split(":")[1].split()[0])
                    break
            gateway_figures = measure(Client(port, b"</CRCLStatus>"), echo=False)
        finally:
            gateway.terminate()
            gateway.wait(timeout=20)
    print(f"CRCL: {N_COMMANDS}-command program, a GetStatus poll after each command until Done; "
          f"{N_STATUS} GetStatus round trips")
    report("gateway + device server", *gateway_figures)
    seconds, _, rtt = gateway_figures
    record("CRCL commands/s (1,000, GetStatus polls)", N_COMMANDS / seconds, "commands/s",
           baseline=N_COMMANDS / baseline[0], baseline_name="TCP echo", goal=500,
           better="higher")
    record("CRCL GetStatus p50", _percentile(rtt, 50), "ms",
           baseline=_percentile(baseline[2], 50), baseline_name="TCP echo", goal=2.0)
    report("baseline: bare TCP echo", *baseline)
    print("(issue 13 quotes NIST's own simulated server at 48 commands/s, 20 ms p50 on this "
          "machine: not measured here)")


if __name__ == "__main__":
    main()
