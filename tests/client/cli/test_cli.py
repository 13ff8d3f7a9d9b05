"""The `landscape` console script as users run it, against a real device server."""
from __future__ import annotations

import getpass
import json
import os
import pty
import select
import signal
import socket
import subprocess
import sys
from concurrent import futures
from pathlib import Path

import grpc
import pytest

from landscape.server.device.states import State
from landscape.v1 import device_service_pb2_grpc

from support import make_keys, start_secured_server, start_server, wait_until

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


def test_watch_json_prints_one_document_a_line_events_and_state(server):
    done = landscape(server.target, "--json", "watch", "--after", "0", "--rate", "20",
                     "--count", "6")
    assert done.returncode == 0, done.stderr
    lines = [json.loads(line) for line in done.stdout.splitlines()]
    assert len(lines) == 6 and all(len(line) == 1 for line in lines)
    events = [line["event"] for line in lines if "event" in line]
    states = [line["state"] for line in lines if "state" in line]
    assert events[0]["sequence"] == "1" and events[0]["event_id"] == "state_changed"
    assert states and len(states[0]["joint_positions"]) == 6


def test_a_json_path_file_loads_and_runs_its_tags(server, tmp_path):
    path_file = tmp_path / "tour.json"
    path_file.write_text(json.dumps({"frame": "joint", "motion": "joint", "points": [
        {"values": [0.3, 0.0, 1.5, 0.0, 1.5, 0.0], "tag_name": "one"},
        {"values": [0.5, 0.1, 1.4, 0.0, 1.4, 0.2], "tag_name": "two"}]}))
    loaded = landscape(server.target, "--json", "path", "load", str(path_file))
    assert loaded.returncode == 0, loaded.stderr
    assert json.loads(loaded.stdout)["path_name"] == "tour"
    assert json.loads(loaded.stdout)["points_loaded"] == 2
    ran = landscape(server.target, "--json", "path", "run", "tour")
    assert ran.returncode == 0, ran.stderr
    assert json.loads(ran.stdout)["tags_reached"] == 2
    assert "tag one reached" in ran.stderr and "tag two reached" in ran.stderr
    assert server.device.feedback().position == pytest.approx([0.5, 0.1, 1.4, 0, 1.4, 0.2],
                                                              abs=1e-4)


def test_io_set_switches_an_output_that_io_get_then_reads(server):
    lamp = 1 << 3   # cell_outputs bit 3: lamp_green in the default cell
    done = landscape(server.target, "io", "set", "2", "--on", hex(lamp),
                     "--description", "lamp on")
    assert done.returncode == 0, done.stderr
    read = landscape(server.target, "--json", "io", "get", "2", "--output")
    assert read.returncode == 0, read.stderr
    assert int(json.loads(read.stdout)["bits_on"]) & lamp
    assert server.device.state is State.UNLOCKED   # the lock was this command's alone


def test_sensor_reads_forces_in_newtons(server):
    done = landscape(server.target, "sensor", "force_sensor")
    assert done.returncode == 0, done.stderr
    assert "(fx fy fz N, tx ty tz N*m)" in done.stdout and "meters" not in done.stdout
    assert len(done.stdout.split(":")[1].split("(")[0].split()) == 6
    laser = landscape(server.target, "sensor", "laser_standoff_sensor")
    assert laser.returncode == 0 and laser.stdout.rstrip().endswith("(meters)"), laser.stderr


def test_tool_get_mounts_the_gripper_and_tool_put_returns_it(server):
    got = landscape(server.target, "tool", "get", "gripper")
    assert got.returncode == 0, got.stderr
    state = json.loads(landscape(server.target, "--json", "tool", "state").stdout)
    assert state["current_ee"] == "gripper"
    put = landscape(server.target, "tool", "put", "gripper")
    assert put.returncode == 0, put.stderr
    assert json.loads(landscape(server.target, "--json", "tool", "state").stdout)[
        "current_ee"] == ""
    assert server.device.state is State.UNLOCKED


def test_a_motion_longer_than_the_timeout_exits_4_and_hands_the_arm_back():
    paced = start_server(lockstep_pace=1.0)   # the move lasts as long as on the arm
    try:
        done = landscape(paced.target, "--timeout", "0.2", "move", "joint", "0.8", "-0.3",
                         "1.2", "0.4", "1.2", "0.5")
        assert done.returncode == 4, done.stderr
        assert "did not end in time" in done.stderr
        assert paced.device.state is State.UNLOCKED   # stopped, drives off, released
    finally:
        paced.stop(grace=None)


def test_a_server_without_the_command_exits_5():
    """A device server built from the contract that carries out none of DeviceService (the
    generated base class answers UNIMPLEMENTED): another vendor's, or an older one."""
    bare = grpc.server(futures.ThreadPoolExecutor(max_workers=2))
    device_service_pb2_grpc.add_DeviceServiceServicer_to_server(
        device_service_pb2_grpc.DeviceServiceServicer(), bare)
    port = bare.add_insecure_port("127.0.0.1:0")
    bare.start()
    try:
        done = landscape(f"127.0.0.1:{port}", "status")
    finally:
        bare.stop(grace=None)
    assert done.returncode == 5, done.stderr
    assert "error:" in done.stderr


class _Recorder(grpc.GenericRpcHandler):
    """A server of no method at all that keeps each call's metadata (UNIMPLEMENTED)."""

    def __init__(self):
        self.calls: list[tuple[str, dict]] = []

    def service(self, details):
        self.calls.append((details.method, dict(details.invocation_metadata)))
        return None


def test_every_call_says_the_cli_acts_for_the_user_at_this_host():
    """identity.md: `landscape-client: landscape-cli`, `landscape-on-behalf-of: user@host`."""
    recorder = _Recorder()
    bare = grpc.server(futures.ThreadPoolExecutor(max_workers=2), handlers=[recorder])
    port = bare.add_insecure_port("127.0.0.1:0")
    bare.start()
    try:
        landscape(f"127.0.0.1:{port}", "status")
    finally:
        bare.stop(grace=None)
    who = f"{getpass.getuser()}@{socket.gethostname()}"
    methods = {method for method, _ in recorder.calls}
    assert "/landscape.v1.SessionService/Connect" in methods, methods
    for method, metadata in recorder.calls:
        assert metadata.get("landscape-client") == "landscape-cli", method
        assert metadata.get("landscape-on-behalf-of") == who, method


def test_tls_and_a_token_file_from_the_flags_or_the_environment(tmp_path):
    keys = make_keys(tmp_path / "keys")
    secured = start_secured_server(keys)
    try:
        tls = ["--tls-ca", str(keys.certs.ca)]
        moved = landscape(secured.target, *tls, "--token-file",
                          str(keys.token_file("operator")), "--json", "move", "joint", "0.3",
                          "0", "1.5", "0", "1.5", "0")
        assert moved.returncode == 0, moved.stderr
        viewer = {**os.environ, "LANDSCAPE_TLS_CA": str(keys.certs.ca),
                  "LANDSCAPE_TOKEN_FILE": str(keys.token_file("viewer"))}
        status = subprocess.run([str(LANDSCAPE), "--target", secured.target, "--json",
                                 "status"], env=viewer, capture_output=True, text=True,
                                timeout=60)
        assert status.returncode == 0, status.stderr   # a viewer reads
        assert json.loads(status.stdout)["joints"] == pytest.approx([0.3, 0, 1.5, 0, 1.5, 0],
                                                                   abs=1e-4)
        refused = subprocess.run([str(LANDSCAPE), "--target", secured.target, "move", "joint",
                                  "0", "0", "1.5", "0", "1.5", "0"], env=viewer,
                                 capture_output=True, text=True, timeout=60)
        assert refused.returncode == 1 and "ROLE_TOO_LOW" in refused.stderr
        no_token = landscape(secured.target, *tls, "status")
        assert no_token.returncode == 1 and "UNAUTHENTICATED" in no_token.stderr
        missing = landscape(secured.target, *tls, "--token-file", str(tmp_path / "nope"),
                            "status")
        assert missing.returncode == 2 and "nope" in missing.stderr
    finally:
        secured.stop(grace=None)


@pytest.fixture
def paced():
    """A device whose motions last as long as on the arm (lock-step at real-time pace)."""
    running = start_server(lockstep_pace=1.0)
    yield running
    running.stop(grace=None)


def _starve(process: subprocess.Popen, server) -> None:
    """Stop the CLI (SIGSTOP: no keep-alive goes out) until the device has ended its session
    and let the arm go, then let it run again."""
    os.kill(process.pid, signal.SIGSTOP)
    try:
        wait_until(lambda: server.device.state is State.UNLOCKED, timeout=20)
    finally:
        os.kill(process.pid, signal.SIGCONT)


def test_a_starved_move_says_the_session_ended_in_the_devices_words_and_exits_6(paced):
    """Issue 25 item 4: the move's wait ends with the device's reason, not 'aborted'."""
    cli = subprocess.Popen([str(LANDSCAPE), "--target", paced.target, "move", "joint", "2.5",
                            "0", "1.57", "0", "1.57", "0", "--speed", "2"],
                           stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    try:
        wait_until(lambda: paced.device.state is State.MOVING, timeout=30)
        _starve(cli, paced)
        _, errors = cli.communicate(timeout=60)
    finally:
        cli.kill()
    assert cli.returncode == 6, errors
    assert "your session ended: no keep-alive for 2 s" in errors
    assert paced.device.state is State.UNLOCKED and not paced.device.status().locked


def test_a_starved_session_script_ends_at_once_without_another_line(paced):
    """Waiting for its next line, `landscape session` hears the device end its session."""
    cli = subprocess.Popen([str(LANDSCAPE), "--target", paced.target, "session"],
                           stdin=subprocess.PIPE, stdout=subprocess.PIPE,
                           stderr=subprocess.PIPE, text=True)
    try:
        cli.stdin.write("lock\n")
        cli.stdin.flush()                       # and no more lines: stdin stays open
        wait_until(lambda: paced.device.state is State.INACTIVE, timeout=30)
        _starve(cli, paced)
        cli.wait(timeout=30)
        errors = cli.stderr.read()
    finally:
        cli.kill()
    assert cli.returncode == 6, errors
    assert "your session ended: no keep-alive for 2 s" in errors
    assert paced.device.state is State.UNLOCKED
