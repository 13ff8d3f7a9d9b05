"""Issue 9, logs: the device server as users start it says in one start-up block what runs
where, "listening" once, warns when the cycle runs without real-time priority, logs one line
per refused command (code, reason, client), obeys --log-level, and lets nothing of pybullet's
(its build banner, "argv[0]=") through."""
from __future__ import annotations

import os
import re
import subprocess
import sys
from pathlib import Path

import grpc
import pytest

from landscape.client import Session
from landscape.v1 import control_pb2, device_service_pb2_grpc, motion_pb2

from support import child_pids

SERVER = ["-m", "landscape.server", "--port", "0", "--audit-log", ""]
# The server without real-time privileges, whoever runs the test: no CAP_SYS_NICE in what it
# execs (root keeps it otherwise) and a real-time priority limit of 0.
WITHOUT_RT = """
import ctypes, os, resource, sys
ctypes.CDLL(None, use_errno=True).prctl(24, 23, 0, 0, 0)   # PR_CAPBSET_DROP, CAP_SYS_NICE
resource.setrlimit(resource.RLIMIT_RTPRIO, (0, 0))
os.execv(sys.executable, [sys.executable, *sys.argv[1:]])
"""
RT_WARNING = "the cycle process runs without real-time guarantees"


class Started:
    """A server process, its target once listening, and all it wrote once stopped."""

    def __init__(self, tmp_path: Path, *args: str, without_rt: bool = False):
        prefix = [sys.executable, "-c", WITHOUT_RT] if without_rt else [sys.executable]
        self.proc = subprocess.Popen([*prefix, *SERVER, "--paths", str(tmp_path / "p.db"), *args],
                                     stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        self.first = self.proc.stdout.readline()
        assert "listening on" in self.first, self.proc.communicate(timeout=30)
        self.target = self.first.split()[-1]

    def cycle_has_real_time_priority(self) -> bool:
        """Whether a child of the server (the cycle process) runs SCHED_FIFO."""
        pid = self.proc.pid
        return any(os.sched_getscheduler(c) == os.SCHED_FIFO for c in child_pids(pid))

    def stop(self) -> tuple[str, str]:
        self.proc.terminate()
        out, err = self.proc.communicate(timeout=30)
        assert self.proc.returncode == 0, err
        return self.first + out, err


def test_start_up_says_what_runs_where_once_and_refusals_in_a_line_each(tmp_path):
    server = Started(tmp_path)                       # real-time clock: the cycle process
    rt = server.cycle_has_real_time_priority()
    with grpc.insecure_channel(server.target) as channel:
        device = device_service_pb2_grpc.DeviceServiceStub(channel)
        for _ in range(2):                            # no lock: refused, twice
            with pytest.raises(grpc.RpcError):
                device.Activate(control_pb2.ActivateRequest(), timeout=10)
        with pytest.raises(grpc.RpcError):
            device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(values=[0.0] * 6), timeout=10)
    out, err = server.stop()
    everything = out + err

    assert err.count("LandScape device server\n") == 1, err
    block = err.split("LandScape device server\n", 1)[1]
    for line in ("cell: built-in default", "controller: realtime clock",
                 f"paths and settings: {tmp_path / 'p.db'}", f"gRPC: {server.target}"):
        assert line in block, block
    assert everything.count("listening") == 1, everything
    assert "argv[0]" not in everything and "pybullet build time" not in everything, everything
    assert (RT_WARNING in err) is not rt, err

    refused = [line for line in err.splitlines() if " refused " in line]
    assert len(refused) == 3, err
    for line, rpc in zip(refused, ("Activate", "Activate", "MoveAbsolute")):
        assert re.search(rf"refused {rpc} from ipv4:127\.0\.0\.1:\d+: ", line), line
        assert "PERMISSION_DENIED NOT_LOCK_HOLDER" in line or "FAILED_PRECONDITION" in line, line


def test_without_real_time_priority_a_warning_and_log_level_warning_keeps_only_it(tmp_path):
    server = Started(tmp_path, "--log-level", "WARNING", without_rt=True)
    assert not server.cycle_has_real_time_priority()
    with grpc.insecure_channel(server.target) as channel:
        with pytest.raises(grpc.RpcError):
            device_service_pb2_grpc.DeviceServiceStub(channel).Activate(
                control_pb2.ActivateRequest(), timeout=10)
    out, err = server.stop()
    warnings = [line for line in err.splitlines() if RT_WARNING in line]
    assert len(warnings) == 1 and "SCHED_FIFO refused" in warnings[0], err
    assert " INFO " not in err and "LandScape device server" not in err, err
    assert "listening on" in out


def test_log_level_debug_still_says_listening_once(tmp_path):
    server = Started(tmp_path, "--clock", "lockstep", "--log-level", "DEBUG")
    out, err = server.stop()
    assert " DEBUG " in err and (out + err).count("listening") == 1, out + err


def test_a_client_name_cannot_forge_log_lines(tmp_path):
    """Issue 25.5: a name with newlines or terminal escapes is written escaped, on its line."""
    forged = "2026-01-01 00:00:00,000 landscape.server INFO stopped"
    name = f"evil\n{forged}\x1b[2K\u2028"
    server = Started(tmp_path, "--clock", "lockstep")
    with grpc.insecure_channel(server.target) as channel, Session(channel, name) as session:
        session.lock()
    out, err = server.stop()
    lines = err.splitlines()
    assert not [line for line in lines if line.startswith(forged)], err
    assert "\x1b" not in err and "\u2028" not in err, err
    opened = [line for line in lines if "opened by" in line]
    assert len(opened) == 1 and "evil\\n2026-01-01" in opened[0] and "\\x1b[2K" in opened[0], err
