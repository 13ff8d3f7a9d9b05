"""`landscape-cell`: every service of a cell as a child process, where each listens, a child
that dies reported (the cell stopped, or the child started again), and the safe stop."""
from __future__ import annotations

import os
import queue
import re
import signal
import socket
import subprocess
import sys
import threading
import time

import grpc
import pytest

from landscape.cell import probe
from landscape.client import Session

from cell_support import make_keys

SUMMARY = re.compile(r"\|\s+(\S+)\s+(device server|CRCL gateway|web supervisor)\s+(\S+)"
                     r".*\(pid (\d+)\)")


class Launched:
    """`python -m landscape.cell --config FILE` with its output read on a thread."""

    def __init__(self, config_file):
        self.process = subprocess.Popen([sys.executable, "-m", "landscape.cell", "--config",
                                         str(config_file)], stdout=subprocess.PIPE,
                                        stderr=subprocess.STDOUT, text=True)
        self.lines: queue.Queue = queue.Queue()
        self.output: list[str] = []
        threading.Thread(target=self._read, daemon=True).start()

    def _read(self) -> None:
        for line in self.process.stdout:
            self.output.append(line.rstrip())
            self.lines.put(line.rstrip())
        self.lines.put(None)

    def wait_for(self, pattern: str, timeout: float = 120.0) -> re.Match:
        deadline = time.monotonic() + timeout
        while True:
            try:
                line = self.lines.get(timeout=max(0.0, deadline - time.monotonic()))
            except queue.Empty:
                raise AssertionError(f"no {pattern!r} within {timeout} s:\n" + self.text())
            if line is None:
                raise AssertionError(f"the launcher ended without {pattern!r}:\n" + self.text())
            match = re.search(pattern, line)
            if match:
                return match

    def up(self) -> dict[str, tuple[str, str, int]]:
        """Waits for the summary: {name: (kind, where, pid)}."""
        self.wait_for(r"is up; Ctrl-C stops it")
        services = {}
        while True:
            try:
                line = self.lines.get(timeout=2)
            except queue.Empty:
                return services
            match = SUMMARY.search(line or "")
            if not match:
                return services
            services[match[1]] = (match[2], match[3], int(match[4]))

    def finish(self, timeout: float = 60.0) -> int:
        code = self.process.wait(timeout)
        time.sleep(0.1)
        return code

    def text(self) -> str:
        return "\n".join(self.output[-60:])

    def close(self) -> None:
        if self.process.poll() is None:
            self.process.kill()
            self.process.wait(30)


@pytest.fixture
def launch(tmp_path):
    launched = []

    def start(text: str) -> Launched:
        path = tmp_path / f"cell{len(launched)}.toml"
        path.write_text(text)
        launched.append(Launched(path))
        return launched[-1]
    yield start
    for each in launched:
        each.close()


def _device(name: str, **extra) -> str:
    lines = [f"[[devices]]", f"name = '{name}'", "port = 0", "clock = 'lockstep'",
             *(f"{key} = {value!r}" for key, value in extra.items())]
    return "\n".join(lines) + "\n"


LOOPBACK_CLIENTS = "[gateway]\nport = 0\n[supervisor]\nport = 0\n"


def test_the_cell_starts_says_where_and_stops_safely(launch, tmp_path):
    keys = make_keys(tmp_path / "var")
    cell = launch(_device("arm1") + _device("arm2", world="press_tending") + LOOPBACK_CLIENTS
                  + "[security]\ntokens = 'var/tokens'\n")
    services = cell.up()
    print("\n".join(f"{name}: {kind} at {where}" for name, (kind, where, _) in services.items()))
    assert [services[n][0] for n in ("arm1", "arm2", "gateway", "supervisor")] == [
        "device server", "device server", "CRCL gateway", "web supervisor"]
    for arm in ("arm1", "arm2"):
        assert probe.grpc_health(services[arm][1]) is None
    assert probe.tcp(services["gateway"][1]) is None
    assert probe.http(services["supervisor"][1]) is None   # its page

    # A lock holder on arm1 when the cell is stopped: its device stops safely all the same.
    from landscape.client import open_channel
    channel = open_channel(services["arm1"][1], token=keys.token("operator"))
    holder = Session(channel, "holder").open()
    holder.lock()
    cell.process.send_signal(signal.SIGTERM)
    assert cell.finish() == 0, cell.text()
    for name in ("gateway", "supervisor", "arm1", "arm2"):
        assert f"cell       | {name} stopped (exit code 0)" in cell.output, cell.text()
    assert any(re.search(r"arm1 +\| .*SIGTERM: stopping \(motion stops, drives off, lock "
                         r"released\)", line) for line in cell.output)
    stopped = [i for i, line in enumerate(cell.output) if " stopped (exit code" in line]
    assert all(client in " ".join(cell.output[i] for i in stopped[:2])   # the clients first
               for client in ("gateway", "supervisor"))
    deadline = time.monotonic() + 10
    while holder.end_status is None:
        assert time.monotonic() < deadline, "the holder's session outlived the cell"
        time.sleep(0.05)
    channel.close()
    lock = '"rpc": "DeviceService/Lock", "request": '    # written when admitted, and done
    assert (tmp_path / "var" / "arm1" / "audit.log").read_text().count(lock) == 2


def test_a_first_run_makes_the_sign_in_tokens_and_says_where_they_are(launch, tmp_path):
    """Devices without tokens (loopback): people still sign in to the supervisor, with a
    token from the folder the launcher makes on the first run."""
    cell = launch(_device("arm1") + "[gateway]\nenabled = false\n[supervisor]\nport = 0\n")
    services = cell.up()
    folder = tmp_path / "var" / "tokens"
    assert sorted(p.name for p in folder.iterdir()) == [
        "admin.tokens", "operator.tokens", "viewer.tokens"]
    assert any(f"made role tokens for signing in to the web supervisor in {folder}" in line
               for line in cell.output), cell.text()
    assert any(f"sign in with a token from {folder}" in line for line in cell.output)
    assert probe.http(services["supervisor"][1]) is None   # the page itself is public
    cell.process.send_signal(signal.SIGINT)
    assert cell.finish() == 0, cell.text()


def test_a_service_that_dies_is_reported_and_the_cell_stops(launch):
    cell = launch(_device("arm1") + "[gateway]\nenabled = false\n[supervisor]\nenabled = false\n")
    services = cell.up()
    os.kill(services["arm1"][2], signal.SIGKILL)
    cell.wait_for(r"arm1 \(device server\) exited on its own with code -9")
    cell.wait_for(r"stopping the cell: arm1 exited with code -9")
    assert cell.finish() == 1


def test_on_failure_a_dead_device_server_comes_back_on_its_port(launch):
    cell = launch(_device("arm1") + "[gateway]\nenabled = false\n[supervisor]\nenabled = false\n"
                  "[launcher]\nrestart = 'on-failure'\nmax_restarts = 1\n")
    services = cell.up()
    target = services["arm1"][1]
    os.kill(services["arm1"][2], signal.SIGKILL)
    cell.wait_for(r"starting arm1 again \(1 of 1\)")
    cell.wait_for(rf"landscape device server listening on {re.escape(target)}")
    assert probe.grpc_health(target) is None
    cell.process.send_signal(signal.SIGINT)
    assert cell.finish() == 0, cell.text()


def test_a_device_server_that_cannot_start_is_shown_and_nothing_stays_running(launch):
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        cell = launch(_device("arm1") + _device("arm2").replace("port = 0", f"port = {port}")
                      + LOOPBACK_CLIENTS)
        cell.wait_for(r"arm2 \(device server\) exited with code 2 before listening")
        cell.wait_for(rf"cannot listen on 127\.0\.0\.1:{port}")
        assert cell.finish() == 1
    assert any("arm1 stopped (exit code 0)" in line for line in cell.output), cell.text()


def test_a_bad_configuration_is_one_line_naming_the_key(tmp_path):
    path = tmp_path / "cell.toml"
    path.write_text("[gateway]\ndevice = 'arm7'\n")
    done = subprocess.run([sys.executable, "-m", "landscape.cell", "--config", str(path)],
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 2
    assert done.stderr.strip().splitlines() == [
        f"landscape-cell: {path}: gateway.device: no device is named 'arm7' (devices: arm1)"]


def test_check_shows_the_built_in_cell_of_make_run(tmp_path):
    done = subprocess.run([sys.executable, "-m", "landscape.cell", "check"], cwd=tmp_path,
                          capture_output=True, text=True, timeout=60)
    assert done.returncode == 0, done.stderr
    assert "--address 127.0.0.1 --port 50051" in done.stdout


def test_certs_and_tokens_commands_make_what_the_server_reads(tmp_path):
    for args in (["certs", "--out", "c", "--host", "cell1.lan", "--client", "gateway"],
                 ["tokens", "--out", "t"]):
        done = subprocess.run([sys.executable, "-m", "landscape.cell", *args], cwd=tmp_path,
                              capture_output=True, text=True, timeout=60)
        assert done.returncode == 0, done.stderr
    names = sorted(p.name for p in (tmp_path / "c").iterdir())
    assert names == ["ca-key.pem", "ca.pem", "gateway-key.pem", "gateway.pem",
                     "opcua-client-key.pem", "opcua-client.pem", "opcua-server-key.pem",
                     "opcua-server.pem", "server-key.pem", "server.pem"]
    assert oct((tmp_path / "c" / "server-key.pem").stat().st_mode & 0o777) == "0o600"
    assert sorted(p.name for p in (tmp_path / "t").iterdir()) == [
        "admin.tokens", "operator.tokens", "viewer.tokens"]
    from cryptography import x509
    cert = x509.load_pem_x509_certificate((tmp_path / "c" / "server.pem").read_bytes())
    names = cert.extensions.get_extension_for_class(x509.SubjectAlternativeName).value
    assert "cell1.lan" in names.get_values_for_type(x509.DNSName)
    # OPC UA's pair: RSA (Basic256Sha256), naming the application the bridge says it is
    from landscape.bridges.opcua.server import application_uri
    from landscape.cell.certs import OPCUA_SERVER_URI
    assert application_uri(str(tmp_path / "c" / "opcua-server.pem")) == OPCUA_SERVER_URI
    with pytest.raises(ValueError, match="RSA"):   # the TLS pair is ECDSA: refused, saying so
        application_uri(str(tmp_path / "c" / "server.pem"))
    ca_before = (tmp_path / "c" / "ca.pem").read_bytes()
    subprocess.run([sys.executable, "-m", "landscape.cell", "certs", "--out", "c"],
                   cwd=tmp_path, check=True, capture_output=True, timeout=60)
    assert (tmp_path / "c" / "ca.pem").read_bytes() == ca_before      # the CA is kept
