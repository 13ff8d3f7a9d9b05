"""The README's grpcurl walkthrough, extracted and run as written against the cell as
`make run` starts it: `python -m landscape.cell` with its built-in cell file (a device server on
the real-time clock, the CRCL gateway, the web supervisor), every port 0 instead of the fixed
ones and its data in a folder of the test's."""
from __future__ import annotations

import contextlib
import re
import signal
import subprocess
import sys
import threading
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


@contextlib.contextmanager
def make_run_cell(folder: Path):
    """`make run`'s cell (cell/cells/local.toml) with ports 0, run from `folder`; yields the
    arm's target once the launcher says the cell is up, then stops it as Ctrl-C does and checks
    that it stopped cleanly."""
    text = resources.files("landscape.cell").joinpath("cells/local.toml").read_text()
    for port in ("50051", "64444", "8080"):
        assert re.search(rf"^port = {port}\b", text, flags=re.M), port
        text = re.sub(rf"^port = {port}\b", "port = 0", text, flags=re.M)
    (folder / "cell.toml").write_text(text)
    cell = subprocess.Popen([sys.executable, "-m", "landscape.cell", "--config", "cell.toml"],
                            cwd=folder, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)
    lines, target = [], None
    try:
        for line in cell.stdout:
            lines.append(line)
            found = re.search(r"arm1 +\| landscape device server listening on (\S+)", line)
            target = found[1] if found else target
            if "is up; Ctrl-C stops it" in line:
                break
        assert target, "".join(lines)
        # The rest of its output is read on, so that the cell never blocks on a full pipe.
        reader = threading.Thread(target=lambda: lines.extend(cell.stdout), daemon=True)
        reader.start()
        yield target
    finally:
        cell.send_signal(signal.SIGINT)
        code = cell.wait(timeout=60)
    assert code == 0, "".join(lines)


@pytest.fixture(scope="module")
def grpcurl() -> Path:
    return installed(GRPCURL, "tools", "grpcurl, which the README's walkthrough calls,")


def test_the_walkthrough_runs_as_written(grpcurl, tmp_path):
    script = walkthrough()
    assert script.count(MAKE_RUN_ADDRESS) == 1, "the walkthrough names make run's address once"
    (tmp_path / ".tools").symlink_to(ROOT / ".tools")   # run where the README says: top folder
    with make_run_cell(tmp_path) as target:
        done = subprocess.run(["bash", "-eu", "-o", "pipefail", "-c",
                               script.replace(MAKE_RUN_ADDRESS, f"ADDR={target}")],
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

