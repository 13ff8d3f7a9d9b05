"""Stored data faults (issue 25.6): a paths file that cannot be read, a row that cannot be
read, a full disk and an empty PathLoad never stop the server nor answer INTERNAL. Real
servers (lock-step clock) on real SQLite files; the full disk is a small tmpfs the test mounts
(conftest.small_disk)."""
from __future__ import annotations

import contextlib
import os
import random
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import grpc
import pytest

from landscape.server.events import alarms
from landscape.server.device.states import State
from landscape.v1 import motion_pb2, settings_pb2, types_pb2

from support import bus_history, error_info, locked_session, start_server, stubs

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
SPEED = settings_pb2.SetSpeedRequest(speed=37, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED)


def _header(name: str) -> motion_pb2.PathHeader:
    return motion_pb2.PathHeader(path_name=name, frame=JOINT,
                                 motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                 offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)


def _load(device, name: str, points: int = 3, **kwargs):
    tags = [types_pb2.TagStruct(joint_values=[0.5 * i / points, -0.2, 1.6, 0, 1.2, 0])
            for i in range(points)]
    return device.PathLoad(iter([motion_pb2.PathLoadRequest(header=_header(name), tags=tags)]),
                           timeout=30, **kwargs)


def _refusal(call) -> grpc.RpcError:
    with pytest.raises(grpc.RpcError) as refused:
        call()
    return refused.value


def _storage_alarms(server) -> list:
    return [e.detail for e in bus_history(server)
            if e.event_id == "alarm" and e.detail.code == alarms.STORAGE]


@contextlib.contextmanager
def _holder(server):
    """The device stub of a lock holder's session, closed after the block."""
    session = locked_session(server)
    try:
        yield stubs(session.channel)[0]
    finally:
        session.close()


def _exists(device, name: str) -> bool:
    """Whether the device has a path of that name (clearing it tells; it is then gone)."""
    try:
        device.PathClearPath(motion_pb2.PathClearPathRequest(path_name=name), timeout=10)
        return True
    except grpc.RpcError as error:
        assert error_info(error).reason == "NOT_FOUND", error
        return False


@pytest.fixture(scope="module")
def good_file(tmp_path_factory) -> Path:
    """A paths file as a server leaves it: paths "a" and "b", speed 37 %."""
    file = tmp_path_factory.mktemp("good") / "paths.sqlite3"
    server = start_server(paths_file=str(file))
    try:
        with _holder(server) as device:
            _load(device, "a")
            _load(device, "b")
            device.SetSpeed(SPEED, timeout=10)
    finally:
        server.stop(grace=None)
    return file


# ---- kinds of unreadable file ----------------------------------------------------------------

def _truncated(file: Path) -> None:
    os.truncate(file, file.stat().st_size // 2)


def _garbage_header(file: Path) -> None:
    with open(file, "r+b") as out:
        out.write(random.Random(1).randbytes(100))


def _corrupted_page(file: Path) -> None:
    """The paths table's first page overwritten."""
    with sqlite3.connect(file) as db:
        page_size = db.execute("PRAGMA page_size").fetchone()[0]
        root = db.execute("SELECT rootpage FROM sqlite_master WHERE name = 'paths'").fetchone()[0]
    db.close()
    with open(file, "r+b") as out:
        out.seek((root - 1) * page_size)
        out.write(random.Random(2).randbytes(page_size))


def _wrong_shape(file: Path) -> None:
    with sqlite3.connect(file) as db:
        db.execute("DROP TABLE paths")
        db.execute("CREATE TABLE paths (id INTEGER PRIMARY KEY, data BLOB)")
    db.close()


STALE_WAL_WRITER = """
import os, sqlite3, sys
db = sqlite3.connect(sys.argv[1])
db.execute("PRAGMA wal_autocheckpoint=0")
body = db.execute("SELECT body FROM paths WHERE name = 'a'").fetchone()[0]
for i in range(40):
    db.execute("INSERT INTO paths VALUES (?, ?)", (f"w{i}", body + " " * 3000))
    db.commit()
db.execute("DELETE FROM paths WHERE name = 'a'")
db.commit()
os._exit(0)     # as if killed: the write-ahead log stays behind, not checkpointed
"""


def _stale_wal(file: Path) -> None:
    """An older backup restored over the file while its newer write-ahead log stayed beside
    it: SQLite replays the log onto pages it was not written for."""
    backup = file.with_name("backup.sqlite3")
    db = sqlite3.connect(backup)
    db.execute("CREATE TABLE settings (id INTEGER PRIMARY KEY CHECK (id = 1), body TEXT NOT NULL)")
    db.execute("CREATE TABLE paths (name TEXT PRIMARY KEY, body TEXT NOT NULL)")
    db.commit()
    db.close()
    subprocess.run([sys.executable, "-c", STALE_WAL_WRITER, str(file)], check=True)
    assert file.with_name(file.name + "-wal").stat().st_size > 0
    shutil.copy(backup, file)
    backup.unlink()


@pytest.mark.parametrize("spoil", [_truncated, _garbage_header, _corrupted_page, _wrong_shape,
                                   _stale_wal], ids=lambda spoil: spoil.__name__.strip("_"))
def test_an_unreadable_paths_file_is_moved_aside_and_the_server_serves(good_file, tmp_path,
                                                                       spoil):
    file = tmp_path / "paths.sqlite3"
    shutil.copy(good_file, file)
    spoil(file)
    # What was there, but the shared-memory index (a cache SQLite rebuilds from the log).
    spoiled = {path.name: path.read_bytes() for path in tmp_path.glob("paths.sqlite3*")
               if not path.name.endswith("-shm")}
    server = start_server(paths_file=str(file))
    try:
        assert server.device.state is State.UNLOCKED
        (alarm,) = _storage_alarms(server)
        kept = sorted(tmp_path.glob("paths.sqlite3.unreadable-*"))
        assert kept and str(kept[0]) in alarm.message, (alarm.message, kept)
        print(alarm.message)
        # Kept as it was, beside its write-ahead log if it had one.
        assert {path.name.replace(kept[0].name, "paths.sqlite3"): path.read_bytes()
                for path in kept if not path.name.endswith("-shm")} == spoiled
        with _holder(server) as device:
            assert not _exists(device, "a")     # nothing could be read: nothing is there
            _load(device, "c")
    finally:
        server.stop(grace=None)
    server = start_server(paths_file=str(file))     # the fresh file works, and lasts
    try:
        assert not _storage_alarms(server)
        with _holder(server) as device:
            assert _exists(device, "c")
    finally:
        server.stop(grace=None)


def test_an_unreadable_row_is_skipped_with_an_alarm_naming_it(good_file, tmp_path):
    file = tmp_path / "paths.sqlite3"
    shutil.copy(good_file, file)
    with sqlite3.connect(file) as db:
        db.execute("UPDATE paths SET body = '{not json' WHERE name = 'a'")
        db.execute("UPDATE settings SET body = '[1, 2' WHERE id = 1")
    db.close()
    server = start_server(paths_file=str(file))
    try:
        messages = sorted(alarm.message for alarm in _storage_alarms(server))
        print(messages)
        assert len(messages) == 2
        assert "'a'" in messages[0] and "settings" in messages[1], messages
        with _holder(server) as device:
            speed = device.GetVelocities(settings_pb2.GetVelocitiesRequest(), timeout=10)
            assert speed.percent_velocity != 37            # the defaults
            assert _exists(device, "b")
            assert _exists(device, "a")    # the unreadable one can be cleared
            device.SetSpeed(SPEED, timeout=10)    # and the settings stored again
    finally:
        server.stop(grace=None)
    server = start_server(paths_file=str(file))
    try:
        assert [a.message for a in _storage_alarms(server)] == []
        assert server.device.settings.speed_percent == 37
    finally:
        server.stop(grace=None)


def test_a_full_disk_is_resource_exhausted_with_an_alarm_and_changes_nothing(small_disk):
    server = start_server(paths_file=str(small_disk.path / "paths.sqlite3"))
    try:
        with _holder(server) as device:
            _load(device, "before")
            small_disk.fill()
            refused = _refusal(lambda: _load(device, "during", points=200))
            assert refused.code() is grpc.StatusCode.RESOURCE_EXHAUSTED, refused
            assert error_info(refused).reason == "STORAGE_FULL"
            refused = _refusal(lambda: device.SetSpeed(SPEED, timeout=10))
            assert refused.code() is grpc.StatusCode.RESOURCE_EXHAUSTED, refused
            speed = device.GetVelocities(settings_pb2.GetVelocitiesRequest(), timeout=10)
            assert speed.percent_velocity != 37                       # unchanged
            (alarm,) = _storage_alarms(server)                        # once, not per call
            assert "full" in alarm.message, alarm.message
            assert not _exists(device, "during")
            small_disk.free()                                         # space again
            _load(device, "after")
            device.SetSpeed(SPEED, timeout=10)
            assert _exists(device, "after") and _exists(device, "before")
            assert len(_storage_alarms(server)) == 2                  # and it said so
    finally:
        server.stop(grace=None)


def test_a_path_load_with_a_header_and_no_points_is_invalid_argument(server):
    with _holder(server) as device:
        refused = _refusal(lambda: device.PathLoad(
            iter([motion_pb2.PathLoadRequest(header=_header("empty"))]), timeout=10))
        assert refused.code() is grpc.StatusCode.INVALID_ARGUMENT, refused
        assert "no points" in refused.details(), refused.details()
        assert not _exists(device, "empty")
