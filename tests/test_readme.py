"""The README's grpcurl walkthrough, extracted and run as written against the device server
as `make run` starts it (`python -m landscape.server`, real-time clock)."""
from __future__ import annotations

import re
import shutil
import subprocess
from pathlib import Path

import pytest

from support import spawned_server

ROOT = Path(__file__).resolve().parents[1]
README = ROOT / "README.md"
GRPCURL = ROOT / ".tools" / "bin" / "grpcurl"
MAKE_RUN_ADDRESS = "ADDR=127.0.0.1:50051"


def walkthrough() -> str:
    """The ```sh blocks between <!-- walkthrough --> and <!-- /walkthrough -->, in order."""
    text = README.read_text()
    section = text.split("<!-- walkthrough -->", 1)[1].split("<!-- /walkthrough -->", 1)[0]
    return "\n".join(re.findall(r"```sh\n(.*?)```", section, flags=re.S))


@pytest.fixture(scope="module")
def grpcurl() -> Path:
    if not GRPCURL.exists():
        if shutil.which("go") is None:
            pytest.skip("Go is not installed, so `make tools` cannot build grpcurl, which the "
                        "README's walkthrough calls as .tools/bin/grpcurl")
        subprocess.run(["make", "-s", "tools"], cwd=ROOT, check=True, timeout=600)
    return GRPCURL


def test_the_walkthrough_runs_as_written(grpcurl, tmp_path):
    script = walkthrough()
    assert script.count(MAKE_RUN_ADDRESS) == 1, "the walkthrough names make run's address once"
    (tmp_path / ".tools").symlink_to(ROOT / ".tools")   # run where the README says: top folder
    with spawned_server("--paths", str(tmp_path / "paths.sqlite3")) as target:
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

