"""Settings written behind (issue 31 item 2, stored_settings.py): a change is in force at once
and in the paths file within the write-behind delay; a stop signal writes what is pending at
once; a server killed outright within the delay restarts without that change (as documented);
with a delay of 0 every change is in the file before its reply.

Each test runs the server as users do (`python -m landscape.server`, real-time clock) so that
it can be killed with SIGKILL, then starts it again on the same file."""
from __future__ import annotations

import contextlib
import json
import signal
import sqlite3
import subprocess
import sys

import grpc

from landscape.client import Session
from landscape.v1 import settings_pb2, types_pb2

from support import stubs, wait_until

DEFAULT_SPEED = 25.0


@contextlib.contextmanager
def _server(paths, *args: str):
    """A spawned device server on `paths`: yields (process, target); killed if still running."""
    proc = subprocess.Popen([sys.executable, "-m", "landscape.server", "--port", "0",
                             "--paths", str(paths), *args],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    try:
        for line in proc.stdout:
            if "listening on" in line:
                break
        else:
            raise AssertionError("the server exited without listening")
        yield proc, line.rsplit(" ", 1)[-1].strip()
    finally:
        if proc.poll() is None:
            proc.kill()
        proc.wait(timeout=20)


def _set_speed(target: str, percent: float) -> None:
    with Session(grpc.insecure_channel(target), "setter") as session:
        session.lock()
        device, _, _ = stubs(session.channel)
        device.SetSpeed(settings_pb2.SetSpeedRequest(
            speed=percent, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED), timeout=10)
        # In force at once, whether written yet or not.
        assert _speed(target) == percent


def _speed(target: str) -> float:
    with grpc.insecure_channel(target) as channel:
        device, _, _ = stubs(channel)
        return device.GetVelocities(settings_pb2.GetVelocitiesRequest(),
                                    timeout=10).percent_velocity


def _stored_speed(paths) -> float | None:
    """What the file holds now (read-only, beside the running server)."""
    with contextlib.closing(sqlite3.connect(f"file:{paths}?mode=ro", uri=True)) as db:
        row = db.execute("SELECT body FROM settings WHERE id = 1").fetchone()
    return None if row is None else json.loads(row[0]).get("speed_percent")


def _restarted_speed(paths) -> float:
    with _server(paths) as (proc, target):
        speed = _speed(target)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=20) == 0
    return speed


def test_a_setting_survives_a_kill_after_its_write_behind_delay(tmp_path):
    paths = tmp_path / "paths.sqlite3"
    with _server(paths) as (proc, target):
        _set_speed(target, 37)
        wait_until(lambda: _stored_speed(paths) == 37, timeout=10)   # written behind
        proc.kill()
        assert proc.wait(timeout=20) == -signal.SIGKILL
    assert _restarted_speed(paths) == 37


def test_a_stop_signal_writes_a_pending_setting_at_once(tmp_path):
    """The delay is a minute, so only the stop can have written it."""
    paths = tmp_path / "paths.sqlite3"
    with _server(paths, "--settings-delay", "60") as (proc, target):
        _set_speed(target, 37)
        assert _stored_speed(paths) in (None, DEFAULT_SPEED)           # not written yet
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=20) == 0                              # well within the delay
    assert _stored_speed(paths) == 37
    assert _restarted_speed(paths) == 37


def test_a_kill_within_the_delay_loses_that_change_as_documented(tmp_path):
    paths = tmp_path / "paths.sqlite3"
    with _server(paths, "--settings-delay", "60") as (proc, target):
        _set_speed(target, 37)
        proc.kill()
        proc.wait(timeout=20)
    assert _restarted_speed(paths) == DEFAULT_SPEED


def test_with_no_delay_a_setting_is_stored_before_its_reply(tmp_path):
    paths = tmp_path / "paths.sqlite3"
    with _server(paths, "--settings-delay", "0") as (proc, target):
        _set_speed(target, 37)
        assert _stored_speed(paths) == 37
        proc.kill()
        proc.wait(timeout=20)
    assert _restarted_speed(paths) == 37
