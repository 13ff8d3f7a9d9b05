"""NIST's reference CRCL client (crcl4java-ui from Maven Central, which `make tools` fetches as
nist_client.pom.xml says) runs programs against the real gateway in its command-line client
mode, and reports success. It polls GetStatus and checks each move's end pose against the
tolerance from the statuses we send."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from crcl_support import EXAMPLES, RunningGateway, needs_examples, reachable_program
from support import ROOT, installed
from test_nist_examples import workstation


@pytest.fixture(scope="module")
def classpath():
    listing = installed(ROOT / ".tools" / "crcl4java" / "classpath.txt", "tools",
                        "NIST's CRCL client (crcl4java-ui, with Java and Maven)")
    if shutil.which("java") is None:
        pytest.skip("Java is not installed: NIST's client cannot run here")
    jars = listing.read_text().strip()
    missing = [jar for jar in jars.split(":") if not Path(jar).exists()]
    if missing:
        pytest.skip(f"{missing[0]} is gone from Maven's cache: `rm -r .tools/crcl4java; make "
                    f"tools` fetches it again")
    return jars


@pytest.fixture
def cell(server):
    """The gateway of the worked example's cell (examples/06_crcl_workstation.toml)."""
    running = RunningGateway(server.target, workstation=workstation())
    yield running
    running.close()


def nist_client(classpath: str, port: int, program: Path) -> str:
    """What NIST's command-line client prints (stdout) running `program`."""
    done = subprocess.run(
        ["java", "-Djava.awt.headless=true", "-cp", classpath, "crcl.ui.DefaultMain",
         "--mode", "CmdLineClient", "--host", "127.0.0.1", "--port", str(port),
         "--program", str(program)], capture_output=True, text=True, timeout=300)
    return done.stdout + "\n(stderr) " + done.stderr[-3000:]


def test_nists_command_line_client_runs_a_program_with_success(gateway, classpath, tmp_path):
    program = tmp_path / "program.xml"
    program.write_bytes(reachable_program())
    out = nist_client(classpath, gateway.port, program)
    assert f"Program {program} succeeded: true" in out, out
    assert out.count("CRCL_DONE") >= 13


def test_nists_client_runs_nists_first_place_on_the_worked_examples_cell(cell, classpath):
    """NIST's programExample's commands 1-9 in NIST's coordinates (the approach lowered to
    where a TX90 reaches), then back up: examples/06_crcl_workstation.xml."""
    program = ROOT / "examples" / "06_crcl_workstation.xml"
    out = nist_client(classpath, cell.port, program)
    assert f"Program {program} succeeded: true" in out, out
    assert "the gripper fetched from the rack" in out


@needs_examples
def test_nists_client_stops_nists_example_where_this_cell_cannot_go_and_shows_why(cell,
                                                                                 classpath):
    """programExample.xml as NIST wrote it: its command 8 approaches 1 m above the table, out
    of the arm's reach (test_nist_examples.py says why no frame helps)."""
    program = EXAMPLES / "programExample.xml"
    out = nist_client(classpath, cell.port, program)
    assert f"Program {program} succeeded: false" in out, out
    assert "CRCL_Error</CommandState><StateDescription>waypoint 1 is out of the arm's reach" in out
