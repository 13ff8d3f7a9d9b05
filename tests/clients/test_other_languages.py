"""The Go and TypeScript clients, as `make clients` builds them (`make test` does first), run
against a real device server: session, lock, activate, MoveAbsolute, its done event, release."""
from __future__ import annotations

import shutil
import subprocess

import pytest

from landscape.server.device.states import State

from support import ROOT, installed

GOAL = [0.5, -0.1, 1.4, 0.2, 1.2, 0.3]


@pytest.fixture(scope="module")
def go_client() -> list[str]:
    return [str(installed(ROOT / "clients" / "go" / "bin" / "landscape-go-client",
                          "clients-go", "The Go client"))]


@pytest.fixture(scope="module")
def ts_client() -> list[str]:
    main = installed(ROOT / "clients" / "ts" / "dist" / "main.js", "clients-ts",
                     "The TypeScript client")
    if shutil.which("node") is None:
        pytest.skip("Node.js is not installed: the TypeScript client cannot run here")
    return ["node", str(main)]


def _goal() -> str:
    return ",".join(str(v) for v in GOAL)


def _check_sequence(done: subprocess.CompletedProcess, server) -> None:
    assert done.returncode == 0, done.stdout + done.stderr
    lines = done.stdout.splitlines()
    steps = [line.split()[0] for line in lines]
    assert steps == ["session", "locked:", "activated", "started", "done", "joints", "released"]
    started, finished = lines[3].split()[1], lines[4].split()[1]
    assert started == finished and started.startswith("MoveAbsolute")
    assert server.device.state is State.UNLOCKED
    assert list(server.device.feedback().position) == pytest.approx(GOAL, abs=1e-5)


def test_the_go_client_completes_its_sequence(go_client, server):
    done = subprocess.run([*go_client, "-target", server.target, "-joints", _goal()],
                          capture_output=True, text=True, timeout=90)
    _check_sequence(done, server)


def test_the_typescript_client_completes_its_sequence(ts_client, server):
    done = subprocess.run([*ts_client, server.target, _goal()], capture_output=True, text=True,
                          timeout=90)
    _check_sequence(done, server)
