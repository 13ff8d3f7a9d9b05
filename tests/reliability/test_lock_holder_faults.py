"""The lock holder dies (SIGKILL) or freezes (SIGSTOP) in the middle of a straight path, as a
real process of its own (issue 17): once the server has noticed, the arm brakes along the
path, on its line, short of its end, comes to rest and then has its drives off (the physics'
own record, on the lock-step clock paced at real time so that a frozen process's keep-alive
timeout and the simulation keep step; how soon, in bench/bench_faults.py)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from landscape.server.cycle.feedback import WALL
from landscape.server.device.states import State
from landscape.robot.controller import EnableState
from landscape.robot.kinematics import Kinematics

from holder_child import A, B
from reliability_support import RowLog, columns
from support import bus_history, distance_to_line, start_server, wait_until


@pytest.fixture
def server():
    running = start_server(lockstep_pace=1.0)
    sessions = running.device.sessions
    # Short enough that a frozen holder is found mid-line (0.5 m at 0.15 m/s), long enough that
    # a busy machine's late keep-alive is no loss (at 0.6 s the holder lost its lock before
    # its SetSpeed, the machine's load at 7).
    sessions.keepalive_interval, sessions.keepalive_timeout = 0.25, 1.5
    yield running
    running.stop(grace=None)


@pytest.mark.parametrize("fault", [signal.SIGKILL, signal.SIGSTOP], ids=["killed", "frozen"])
def test_a_lock_holder_that_dies_or_freezes_mid_path_leaves_the_arm_at_rest_on_it(server,
                                                                                    fault):
    device = server.device
    child = subprocess.Popen([sys.executable, str(Path(__file__).parent / "holder_child.py"),
                              server.target], stdout=subprocess.PIPE, text=True)
    try:
        line = child.stdout.readline()
        assert line.startswith("moving"), line
        command_id = line.split()[1]
        wait_until(lambda: device.path_runs.last_tag == ("line", "a"), timeout=60)
        log = RowLog(server.link.feedback)
        os.kill(child.pid, fault)
        wait_until(lambda: device.state is State.UNLOCKED, timeout=10)
        raw = log.close()
        rows = columns(raw)
    finally:
        child.kill()
        if fault == signal.SIGSTOP:
            os.kill(child.pid, signal.SIGCONT)
        child.wait(10)
    history = bus_history(server)
    lost = next(e for e in history if e.event_id == "alarm" and e.detail.code == 101)
    ended = next(e for e in history if e.event_id in ("command_done", "command_aborted")
                 and e.detail.command_id == command_id)
    assert ended.event_id == "command_aborted"          # stopped short of B, not finished
    # The cycles the physics ran after the server noticed (stamped on one wall clock with
    # the alarm): moving at first, then at rest, then the drives off, and at rest since.
    noticed = int(np.argmax(raw[:, WALL] >= lost.time))
    off = noticed + int(np.argmax(rows["enable"][noticed:] == EnableState.DISABLED.value))
    assert rows["enable"][off] == EnableState.DISABLED.value, "the drives never went off"
    assert np.max(np.abs(rows["qd"][noticed])) > 1e-3 and off > noticed
    print(f"{fault.name}: at rest with the drives off {rows['t'][off] - rows['t'][noticed]:.3f}"
          f" s (simulated) after the loss was noticed")
    assert np.max(np.abs(rows["qd"][off:])) < 1e-3   # at rest, and stays so
    # Every cycle from the moment before the loss until rest: the tool tip on the line.
    kin = Kinematics(device.arm)
    tips = (kin.forward(rows["q"]) @ device.settings.tool_offset)[:, :3, 3]
    assert np.max(distance_to_line(tips, np.array(A), np.array(B))) < 1e-3
    assert not device.status().locked
