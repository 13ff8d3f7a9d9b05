"""NIST's reference CRCL client (crcl4java-ui from Maven Central, which `make tools` fetches as
nist_client.pom.xml says) runs a program against the real gateway in its command-line client
mode, and reports success. It polls GetStatus and checks each MoveTo's end pose against the
tolerance from the statuses we send."""
from __future__ import annotations

import shutil
import subprocess
from pathlib import Path

import pytest

from crcl_support import reachable_program
from support import ROOT, installed


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


def test_nists_command_line_client_runs_a_program_with_success(gateway, classpath, tmp_path):
    program = tmp_path / "program.xml"
    program.write_bytes(reachable_program())
    done = subprocess.run(
        ["java", "-Djava.awt.headless=true", "-cp", classpath, "crcl.ui.DefaultMain",
         "--mode", "CmdLineClient", "--host", "127.0.0.1", "--port", str(gateway.port),
         "--program", str(program)], capture_output=True, text=True, timeout=300)
    assert f"Program {program} succeeded: true" in done.stdout, done.stdout + done.stderr[-3000:]
    assert done.stdout.count("CRCL_DONE") >= 13
