"""The Go and TypeScript clients, built as `make clients` builds them and run against a real
device server: session, lock, activate, MoveAbsolute, its done event, release."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from landscape.server.states import State

ROOT = Path(__file__).resolve().parents[2]
GOAL = [0.5, -0.1, 1.4, 0.2, 1.2, 0.3]


def _build(target: str, needs: tuple[str, ...]) -> None:
    missing = [tool for tool in needs if shutil.which(tool) is None]
    if missing:
        pytest.skip(f"{' and '.join(missing)} not installed: cannot build the {target} client "
                    f"(`make {target}`)")
    subprocess.run(["make", "-s", target], cwd=ROOT, check=True, timeout=900)


@pytest.fixture(scope="module")
def go_client() -> list[str]:
    _build("clients-go", ("go",))
    return [str(ROOT / "clients" / "go" / "bin" / "landscape-go-client")]


@pytest.fixture(scope="module")
def ts_client() -> list[str]:
    _build("clients-ts", ("node", "npm"))
    return ["node", str(ROOT / "clients" / "ts" / "dist" / "main.js")]


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
