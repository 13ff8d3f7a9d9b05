"""The README's tour, extracted and run as written against the cell as `make run` starts it:
`python -m landscape.cell` with its built-in cell file (a device server on the real-time clock,
the CRCL gateway, the web supervisor), every port 0 instead of the fixed ones and its data in
a folder of the test's. The grpcurl walkthrough, then the `landscape` command's lines and the
CRCL program."""
from __future__ import annotations

import contextlib
import os
import re
import signal
import subprocess
import sys
import threading
from dataclasses import dataclass
from importlib import resources
from pathlib import Path

import pytest

from support import installed

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
GRPCURL = ROOT / ".tools" / "bin" / "grpcurl"
MAKE_RUN_ADDRESS = "ADDR=127.0.0.1:50051"


def walkthrough() -> str:
    """The ```sh blocks between <!-- walkthrough --> and <!-- /walkthrough -->, in order."""
    text = README.read_text()
    section = text.split("<!-- walkthrough -->", 1)[1].split("<!-- /walkthrough -->", 1)[0]
    return "\n".join(re.findall(r"```sh\n(.*?)```", section, flags=re.S))


def tour_block(heading: str) -> list[str]:
    """The lines of the first ```sh block under `heading` (comments cut off)."""
    section = README.read_text().split(heading, 1)[1]
    block = re.search(r"```sh\n(.*?)```", section, flags=re.S).group(1)
    return [line.split("  #")[0].strip() for line in block.splitlines() if line.strip()]


@dataclass
class Cell:
    folder: Path
    target: str      # the arm's
    gateway: str     # the CRCL gateway's


@pytest.fixture(scope="module")
def cell(tmp_path_factory):
    with make_run_cell(tmp_path_factory.mktemp("cell")) as running:
        yield running


@contextlib.contextmanager
def make_run_cell(folder: Path):
    """`make run`'s cell (cell/cells/local.toml) with ports 0, run from `folder`; yields it
    once the launcher says the cell is up, then stops it as Ctrl-C does and checks that it
    stopped cleanly."""
    text = resources.files("landscape.cell").joinpath("cells/local.toml").read_text()
    for port in ("50051", "64444", "8080", "9464"):   # 9464: /metrics
        assert re.search(rf"^port = {port}\b", text, flags=re.M), port
        text = re.sub(rf"^port = {port}\b", "port = 0", text, flags=re.M)
    (folder / "cell.toml").write_text(text)
    cell = subprocess.Popen([sys.executable, "-m", "landscape.cell", "--config", "cell.toml"],
                            cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    lines, found = [], {}
    try:
        for line in cell.stdout:
            lines.append(line)
            for key, pattern in (("target", r"arm1 +\| landscape device server listening on (\S+)"),
                                 ("gateway", r"gateway +\| CRCL gateway listening on (\S+)")):
                match = re.search(pattern, line)
                found[key] = match[1] if match else found.get(key)
            if "is up; Ctrl-C stops it" in line:
                break
        assert found.get("target") and found.get("gateway"), "".join(lines)
        # The rest of its output is read on, so that the cell never blocks on a full pipe.
        reader = threading.Thread(target=lambda: lines.extend(cell.stdout), daemon=True)
        reader.start()
        yield Cell(folder, found["target"], found["gateway"])
    finally:
        cell.send_signal(signal.SIGINT)
        code = cell.wait(timeout=60)
    assert code == 0, "".join(lines)


@pytest.fixture(scope="module")
def grpcurl() -> Path:
    return installed(GRPCURL, "tools", "grpcurl, which the README's walkthrough calls,")


def test_the_walkthrough_runs_as_written(grpcurl, cell):
    script = walkthrough()
    assert script.count(MAKE_RUN_ADDRESS) == 1, "the walkthrough names make run's address once"
    tmp_path = cell.folder
    (tmp_path / ".tools").symlink_to(ROOT / ".tools")   # run where the README says: top folder
    done = subprocess.run(["bash", "-eu", "-o", "pipefail", "-c",
                           script.replace(MAKE_RUN_ADDRESS, f"ADDR={cell.target}")],
                          cwd=tmp_path, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stdout + done.stderr
    out = done.stdout
    lease = re.search(r'"lease": "([^"]+)"', out)
    assert lease and '"ret_msg": "locked"' in out
    for shown in ('"ret_msg": "drives on"', '"ret_code": "RETURN_CODE_CMD_STARTED_OK"',
                  '"phase": "PHASE_STARTED"', '"phase": "PHASE_DONE"',
                  '"ret_msg": "drives off"', '"ret_msg": "released"'):
        assert shown in out, shown
    command_id = re.search(r'"command_id": "(MoveAbsolute-\d+)"', out).group(1)
    events = (tmp_path / "var" / "events.json").read_text()
    assert events.count(f'"command_id": "{command_id}"') == 2   # its started and done events
    joints = re.search(r'"joint_position": \[([^\]]*)\]', out).group(1)
    assert [round(float(q), 4) for q in joints.split(",")] == [0.5, 0, 1.57, 0, 1.57, 0]



def test_the_tours_landscape_lines_and_crcl_program_run(cell):
    """Every line of the `landscape` command's block (but `watch`, which runs until Ctrl-C),
    then the CRCL program, from the top folder with .venv/bin on the PATH as written."""
    env = {**os.environ, "LANDSCAPE_TARGET": cell.target,
           "PATH": f"{Path(sys.executable).parent}:{os.environ['PATH']}"}
    lines = [line for line in tour_block("### The `landscape` command") if " watch" not in line]
    lines += tour_block("### CRCL")
    assert len(lines) == 5 and lines[-1].endswith("landscape crcl run examples/05_crcl_program.xml")
    lines[-1] += f" --gateway {cell.gateway}"
    for line in lines:
        done = subprocess.run(["bash", "-eu", "-o", "pipefail", "-c", line], cwd=ROOT, env=env,
                              capture_output=True, text=True, timeout=180)
        assert done.returncode == 0, (line, done.stdout, done.stderr)
    assert "9 commands done" in done.stdout
