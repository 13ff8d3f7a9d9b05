"""The program runner (landscape-crcl-run) against the real gateway: NIST's example programs
and one the arm can do."""
from __future__ import annotations

import io
import json
import subprocess
import sys
from pathlib import Path

import pytest
from lxml import etree

from landscape.gateway.run import ProgramFailed, run

from crcl_support import EXAMPLES, needs_examples, program, reachable_program


def test_a_reachable_program_runs_to_completion_with_progress_per_command(gateway, tmp_path):
    path = tmp_path / "program.xml"
    path.write_bytes(reachable_program())
    out = io.StringIO()
    assert run(path, f"127.0.0.1:{gateway.port}", out=out) == 13
    lines = out.getvalue().splitlines()
    assert len(lines) == 13 and all("CRCL_Done" in line for line in lines), lines
    assert lines[7].startswith("[8/13] MoveThroughTo (CommandID 8): CRCL_Done")


# NIST's example programs, plain and with a Name on every element (the same commands)
EXAMPLE = pytest.mark.parametrize("example", ["programExample.xml", "programExampleWithNames.xml"])
ALL = pytest.mark.parametrize("example", ["programAll.xml", "programAllWithNames.xml"])


@needs_examples
@EXAMPLE
def test_the_example_program_stops_at_the_first_command_the_device_cannot_do(gateway, example):
    out = io.StringIO()
    with pytest.raises(ProgramFailed) as failure:
        run(EXAMPLES / example, f"127.0.0.1:{gateway.port}", out=out)
    # CommandID 7 is SetEndEffector with no tool on the arm
    assert "(SetEndEffector, CommandID 7) failed: no end effector on the arm" in str(failure.value)
    assert out.getvalue().splitlines()[-1].startswith("[7/41] SetEndEffector (CommandID 7): "
                                                      "CRCL_Error")


@needs_examples
@EXAMPLE
def test_the_example_program_without_tool_commands_fails_where_the_arm_cannot_reach(
        gateway, tmp_path, example):
    # CommandID 8 moves to X = 1.5 m, beyond the TX90's reach
    tree = etree.parse(str(EXAMPLES / example))
    for element in tree.getroot().findall("MiddleCommand"):
        if element.get("{http://www.w3.org/2001/XMLSchema-instance}type") in (
                "SetEndEffectorType", "OpenToolChangerType", "CloseToolChangerType"):
            tree.getroot().remove(element)
    path = tmp_path / "moves-only.xml"
    tree.write(str(path))
    with pytest.raises(ProgramFailed, match=r"command 6 \(MoveThroughTo, CommandID 8\) failed: "
                                            r"waypoint 1 is out of the arm's reach, nothing moved"):
        run(path, f"127.0.0.1:{gateway.port}", out=io.StringIO())


@needs_examples
@ALL
def test_program_all_stops_at_its_first_command(gateway, example):
    with pytest.raises(ProgramFailed, match=r"command 1 \(ActuateJoints, CommandID 2\) failed: "
                                            r"JointForceTorque on joint 3"):
        run(EXAMPLES / example, f"127.0.0.1:{gateway.port}", out=io.StringIO())


@needs_examples
def test_the_command_line_runner(gateway, tmp_path):
    path = tmp_path / "program.xml"
    path.write_bytes(reachable_program())
    done = subprocess.run([sys.executable, "-m", "landscape.gateway.run", str(path), "--gateway",
                           f"127.0.0.1:{gateway.port}"], capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines()[-1] == "program done: 13 commands"
    failed = subprocess.run([sys.executable, "-m", "landscape.gateway.run",
                             str(EXAMPLES / "programAll.xml"), "--gateway",
                             f"127.0.0.1:{gateway.port}"], capture_output=True, text=True, timeout=120)
    assert failed.returncode == 1
    assert "program failed: command 1 (ActuateJoints, CommandID 2) failed" in failed.stderr


def test_the_landscape_cli_runs_a_program_through_the_gateway(gateway, tmp_path):
    """`landscape crcl run` (issue 15) uses this runner."""
    path = tmp_path / "program.xml"
    path.write_bytes(reachable_program())
    landscape = Path(sys.executable).with_name("landscape")   # the installed console script
    done = subprocess.run([str(landscape), "--json", "crcl", "run", str(path), "--gateway",
                           f"127.0.0.1:{gateway.port}"], capture_output=True, text=True,
                          timeout=120)
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert len(result["commands"]) == 13
    assert all(c["state"] == "CRCL_Done" for c in result["commands"])


def test_the_readmes_example_program_runs(gateway):
    """examples/05_crcl_program.xml, which the README's tour runs with `landscape crcl run`."""
    out = io.StringIO()
    example = Path(__file__).resolve().parents[2] / "examples" / "05_crcl_program.xml"
    assert run(example, f"127.0.0.1:{gateway.port}", out=out) == 9
    assert all("CRCL_Done" in line for line in out.getvalue().splitlines()), out.getvalue()


def test_a_failed_run_frees_the_lock_for_the_next_at_once(gateway, tmp_path):
    """The runner closes its connection however the program ends, and the gateway's next
    session waits for the last one's end: a program run right after a failed one starts."""
    failing = tmp_path / "failing.xml"
    failing.write_bytes(program([("MoveTo", "<MoveStraight>false</MoveStraight>"
                                            "<EndPosition><Point><X>2.5</X><Y>1</Y><Z>1</Z>"
                                            "</Point><XAxis><I>1</I><J>0</J><K>0</K></XAxis>"
                                            "<ZAxis><I>0</I><J>0</J><K>-1</K></ZAxis>"
                                            "</EndPosition>")]))
    good = tmp_path / "good.xml"
    good.write_bytes(reachable_program())
    for _ in range(3):
        with pytest.raises(ProgramFailed, match="out of the arm's reach"):
            run(failing, f"127.0.0.1:{gateway.port}", out=io.StringIO())
        assert run(good, f"127.0.0.1:{gateway.port}", out=io.StringIO()) == 13
