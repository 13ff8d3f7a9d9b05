"""The `landscape` console script as users run it, against a real device server."""
from __future__ import annotations

import json
import os
import pty
import select
import subprocess
import sys
from pathlib import Path

import pytest

from landscape.server.states import State

LANDSCAPE = Path(sys.executable).with_name("landscape")   # the installed console script


def landscape(target: str, *args: str, stdin: str | None = None, timeout: float = 60):
    return subprocess.run([str(LANDSCAPE), "--target", target, *args], input=stdin,
                          capture_output=True, text=True, timeout=timeout)


def on_a_terminal(target: str, *args: str, timeout: float = 60) -> tuple[int, str]:
    """Run in a pseudo-terminal, as a person would (progress bars only show on a terminal)."""
    pid, fd = pty.fork()
    if pid == 0:
        os.execv(str(LANDSCAPE), [str(LANDSCAPE), "--target", target, *args])
    output = b""
    while select.select([fd], [], [], timeout)[0]:
        try:
            chunk = os.read(fd, 4096)
        except OSError:   # the child closed the terminal
            break
        if not chunk:
            break
        output += chunk
    _, status = os.waitpid(pid, 0)
    return os.waitstatus_to_exitcode(status), output.decode(errors="replace")


def test_status_json_parses(server):
    done = landscape(server.target, "--json", "status")
    assert done.returncode == 0, done.stderr
    status = json.loads(done.stdout)
    assert status["state"] == "UNLOCKED" and status["locked"] is False
    assert len(status["joints"]) == 6
    assert status["units"] == {"linear": "meters", "angular": "radians"}


def test_a_refused_command_exits_non_zero_with_the_servers_message(server):
    done = landscape(server.target, "move", "joint", "9", "0", "1.57", "0", "1.57", "0")
    assert done.returncode == 1
    assert "joint 1 target 9 rad is outside its range" in done.stderr
    assert "PARAM_OUT_OF_RANGE" in done.stderr
    assert server.device.state is State.UNLOCKED   # handed back after the refusal
    as_json = landscape(server.target, "--json", "move", "joint", "9", "0", "0", "0", "0", "0")
    error = json.loads(as_json.stderr)["error"]
    assert (as_json.returncode, error["reason"], error["ret_code"]) == (1, "PARAM_OUT_OF_RANGE", -3)


def test_a_move_waits_for_done_then_prints_the_position(server):
    done = landscape(server.target, "--json", "move", "joint", "0.4", "-0.2", "1.4", "0", "1.5",
                     "0")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["done"]["event_id"] == "command_done"
    assert result["position"]["joint_position"] == pytest.approx([0.4, -0.2, 1.4, 0, 1.5, 0],
                                                                 abs=1e-5)


def test_a_path_file_runs_with_a_progress_bar(server, tmp_path):
    path_file = tmp_path / "square.csv"
    path_file.write_text("tag_name,j1,j2,j3,j4,j5,j6\n"
                         "a,0.2,0,1.57,0,1.57,0\nb,0.4,0.1,1.4,0,1.57,0\n"
                         ",0.5,0.1,1.4,0,1.57,0\nc,0.3,0,1.57,0,1.57,0\n")
    code, screen = on_a_terminal(server.target, "path", "run", "square", "--file", str(path_file))
    assert code == 0, screen
    assert "[####" in screen and "3/3" in screen           # click's bar, full at the end
    assert "path square done" in screen and "3 tags reached" in screen


def test_a_session_script_locks_moves_and_releases_in_one_process(server):
    script = "lock\nactivate\n# a comment\nmove joint 0.3 0 1.57 0 1.57 0\ndeactivate\nrelease\n"
    done = landscape(server.target, "session", stdin=script)
    assert done.returncode == 0, done.stderr
    assert "locked by landscape-cli" in done.stdout and "MoveAbsolute" in done.stdout
    assert server.device.state is State.UNLOCKED


def test_a_failing_session_line_stops_the_script_and_hands_the_device_back(server):
    done = landscape(server.target, "session", stdin="lock\nactivate\nmove joint 9 0 0 0 0 0\n"
                                                     "move joint 0.3 0 1.57 0 1.57 0\n")
    assert done.returncode == 1 and "outside its range" in done.stderr
    assert "MoveAbsolute" not in done.stdout          # the line after the failure did not run
    assert server.device.state is State.UNLOCKED


def test_lock_alone_is_a_usage_error_that_points_to_session(server):
    done = landscape(server.target, "lock")
    assert done.returncode == 2 and "landscape session" in done.stderr


def test_exit_codes_for_no_server_and_commands_not_built(server):
    unreachable = landscape("127.0.0.1:1", "--connect-timeout", "0.5", "status")
    assert unreachable.returncode == 3 and "no device server" in unreachable.stderr
    refused = landscape(server.target, "io", "get", "9")     # no unit 9: the device refuses
    assert refused.returncode == 1 and "no I/O unit 9" in refused.stderr


def test_crcl_run_without_a_gateway_says_so(tmp_path):
    program = tmp_path / "p.xml"
    program.write_text('<CRCLProgram><InitCanon><CommandID>1</CommandID></InitCanon>'
                       '<EndCanon><CommandID>2</CommandID></EndCanon></CRCLProgram>')
    done = landscape("127.0.0.1:1", "crcl", "run", str(program), "--gateway", "127.0.0.1:1")
    assert done.returncode == 1 and "cannot reach the CRCL gateway at 127.0.0.1:1" in done.stderr
