"""The device server killed (SIGKILL) and started again on the same files (issue 17): the
stored paths and settings are intact, a path whose load was half sent left nothing, and the
killed server's cycle process did not outlive it."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import grpc
import pytest

from landscape.client import Session
from landscape.v1 import motion_pb2, settings_pb2, types_pb2

from support import child_pids, error_info, stubs, wait_until

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME


def _start(paths: Path) -> tuple[subprocess.Popen, str]:
    """The device server as users start it (real-time clock), on `paths`; (process, target)."""
    proc = subprocess.Popen([sys.executable, "-m", "landscape.server", "--port", "0",
                             "--paths", str(paths)],
                            stdout=subprocess.PIPE, stderr=subprocess.DEVNULL, text=True)
    for line in proc.stdout:
        if "listening on" in line:
            return proc, line.rsplit(" ", 1)[-1].strip()
    raise AssertionError("the server exited without listening")


def _cycle_process(pid: int) -> int:
    """The server's cycle process (its child started by multiprocessing's spawn)."""
    for child in child_pids(pid):
        if b"spawn_main" in Path(f"/proc/{child}/cmdline").read_bytes():
            return child
    raise AssertionError("no cycle process")


def _alive(pid: int) -> bool:
    try:
        return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0] != "Z"
    except (FileNotFoundError, ProcessLookupError):
        return False


def _header(name: str) -> motion_pb2.PathHeader:
    return motion_pb2.PathHeader(path_name=name, frame=JOINT,
                                 motion_type=types_pb2.MOTION_TYPE_JOINT_MOTION,
                                 offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)


def _tags(n: int) -> list:
    return [types_pb2.TagStruct(joint_values=[0.1 * i, 0, 1.5708, 0, 1.5708, 0])
            for i in range(1, n + 1)]


def test_a_killed_server_keeps_its_paths_and_settings_and_no_half_loaded_path(tmp_path):
    paths = tmp_path / "paths.sqlite3"
    proc, target = _start(paths)
    try:
        cycle = _cycle_process(proc.pid)
        with grpc.insecure_channel(target) as channel:
            session = Session(channel, "before").open()
            session.lock()
            device = stubs(session.channel)[0]
            device.SetSpeed(settings_pb2.SetSpeedRequest(
                speed=37, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED), timeout=5)
            device.SetAcceleration(settings_pb2.SetAccelerationRequest(
                accel=45, attribute=types_pb2.ACCEL_TYPE_PERCENT_ACCEL), timeout=5)
            device.PathLoad(iter([motion_pb2.PathLoadRequest(header=_header("kept"),
                                                             tags=_tags(3))]), timeout=30)
            sent, never = threading.Event(), threading.Event()

            def half():
                yield motion_pb2.PathLoadRequest(header=_header("half"), tags=_tags(2))
                sent.set()
                never.wait(30)   # the rest never comes: the server is killed first

            loading = device.PathLoad.future(half(), timeout=60)
            assert sent.wait(10)
            time.sleep(0.3)   # the first message is in the server
            os.kill(proc.pid, signal.SIGKILL)
            proc.wait(10)
            never.set()
            with pytest.raises(grpc.RpcError):
                loading.result()
        wait_until(lambda: not _alive(cycle), timeout=10)   # no orphan drives the arm
    finally:
        proc.kill()
        proc.wait(10)
    proc, target = _start(paths)
    try:
        with grpc.insecure_channel(target) as channel, Session(channel, "after") as session:
            device = stubs(session.channel)[0]
            velocities = device.GetVelocities(settings_pb2.GetVelocitiesRequest(), timeout=5)
            accelerations = device.GetAccelerations(settings_pb2.GetAccelerationsRequest(),
                                                    timeout=5)
            assert (velocities.percent_velocity, accelerations.percent_accel) == (37, 45)
            session.lock()
            with pytest.raises(grpc.RpcError) as refused:
                device.PathClearPath(motion_pb2.PathClearPathRequest(path_name="half"),
                                     timeout=5)
            assert error_info(refused.value).reason == "NOT_FOUND"
            device.PathClearPath(motion_pb2.PathClearPathRequest(path_name="kept"), timeout=5)
    finally:
        proc.terminate()
        assert proc.wait(20) == 0
