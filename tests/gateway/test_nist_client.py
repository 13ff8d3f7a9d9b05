"""NIST's reference CRCL client (crcl4java-ui, Maven Central) runs a program against the real
gateway in its command-line client mode, and reports success. It polls GetStatus and checks
each MoveTo's end pose against the tolerance from the statuses we send."""
from __future__ import annotations

import shutil
import subprocess

import pytest

from crcl_support import reachable_program

CRCL4JAVA = ("com.github.wshackle", "crcl4java-ui", "1.8")
POM = f"""<project xmlns="http://maven.apache.org/POM/4.0.0">
  <modelVersion>4.0.0</modelVersion>
  <groupId>landscape.tests</groupId><artifactId>nist-crcl-client</artifactId><version>0</version>
  <dependencies><dependency><groupId>{CRCL4JAVA[0]}</groupId><artifactId>{CRCL4JAVA[1]}</artifactId>
    <version>{CRCL4JAVA[2]}</version></dependency></dependencies>
</project>"""


@pytest.fixture(scope="module")
def classpath(tmp_path_factory):
    for tool in ("java", "mvn"):
        if shutil.which(tool) is None:
            pytest.skip(f"{tool} is not installed: NIST's Java client cannot run here")
    folder = tmp_path_factory.mktemp("crcl4java")
    (folder / "pom.xml").write_text(POM)
    try:
        fetched = subprocess.run(["mvn", "-q", "-B", "dependency:build-classpath",
                                  "-Dmdep.outputFile=cp.txt"], cwd=folder, capture_output=True,
                                 text=True, timeout=600)
    except subprocess.TimeoutExpired:
        pytest.skip("Maven did not fetch crcl4java-ui within 10 minutes")
    if fetched.returncode != 0:
        pytest.skip(f"Maven could not fetch {':'.join(CRCL4JAVA)}: {fetched.stdout[-500:]}")
    return (folder / "cp.txt").read_text().strip()


def test_nists_command_line_client_runs_a_program_with_success(gateway, classpath, tmp_path):
    program = tmp_path / "program.xml"
    program.write_bytes(reachable_program())
    done = subprocess.run(
        ["java", "-Djava.awt.headless=true", "-cp", classpath, "crcl.ui.DefaultMain",
         "--mode", "CmdLineClient", "--host", "127.0.0.1", "--port", str(gateway.port),
         "--program", str(program)], capture_output=True, text=True, timeout=300)
    assert f"Program {program} succeeded: true" in done.stdout, done.stdout + done.stderr[-3000:]
    assert done.stdout.count("CRCL_DONE") >= 13
