"""Reliability (issue 17): the gateway restarted while a CRCL client is connected and its arm
moves. The client's connection ends cleanly (closed, not hung or reset mid-document), the
device stops the arm and frees the lock, and the client reconnects to the new gateway and
carries on. The gateway runs as users start it (`python -m landscape.gateway`)."""
from __future__ import annotations

import signal
import socket
import subprocess
import sys

import pytest

from landscape.server.device.states import State

from support import wait_until

from crcl_support import RawClient, command, field, pose
from test_gateway import MOVE, point


def _free_port() -> int:
    with socket.socket() as probe:
        probe.bind(("127.0.0.1", 0))
        return probe.getsockname()[1]


class GatewayProcess:
    def __init__(self, device: str, port: int, *args: str):
        self.process = subprocess.Popen(
            [sys.executable, "-m", "landscape.gateway", "--device", device, "--port", str(port),
             *args],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = self.process.stdout.readline()
        assert "CRCL gateway listening on" in line, (line, self.process.stderr.read()[-2000:])

    def stop(self) -> None:
        """SIGTERM: the gateway exits 0 without a traceback."""
        self.process.send_signal(signal.SIGTERM)
        _, errors = self.process.communicate(timeout=20)
        assert self.process.returncode == 0, errors[-2000:]
        assert "Traceback" not in errors and " ERROR " not in errors, errors[-2000:]


@pytest.fixture
def port():
    return _free_port()


def test_a_gateway_restart_ends_the_connection_cleanly_and_the_client_reconnects(server, port):
    gateway = GatewayProcess(server.target, port)
    client = RawClient(port, timeout=20)
    try:
        assert field(client.run("InitCanon", 1), "CommandState") == "CRCL_Done"
        client.run("SetTransSpeed", 2, '<TransSpeed xsi:type="TransSpeedRelativeType">'
                                       '<Fraction>0.05</Fraction></TransSpeed>')
        client.send(command("MoveTo", 3, MOVE.format("true") + pose(0.5, 0.3, 0.5)))
        wait_until(lambda: server.device.state is State.MOVING, timeout=20)

        gateway.stop()
        with pytest.raises(ConnectionError):   # closed: the end of the stream (a read that
            client.status()                    # waited out its timeout raises TimeoutError)
        # the device saw its CRCL session end: the arm stopped on its path, the lock is free
        wait_until(lambda: server.device.state is State.UNLOCKED, timeout=10)
    finally:
        client.close()

    gateway = GatewayProcess(server.target, port)     # the same port, as a restarted service
    client = RawClient(port, timeout=20)
    try:
        assert field(client.run("InitCanon", 1), "CommandState") == "CRCL_Done"
        done = client.run("MoveTo", 2, MOVE.format("false") + pose(0.5, -0.1, 0.6))
        assert field(done, "CommandState") == "CRCL_Done", done
        assert point(done) == pytest.approx((0.5, -0.1, 0.6), abs=1e-4)
    finally:
        client.close()
        gateway.stop()
