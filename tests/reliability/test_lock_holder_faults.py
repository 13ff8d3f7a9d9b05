"""The lock holder dies (SIGKILL) or freezes (SIGSTOP) in the middle of a straight path, as a
real process of its own (issue 17): the arm brakes along the path, on its line, and is at
rest with the drives off within 1 s of simulated time after the server noticed (the
physics' own record, on the lock-step clock paced at real time so that a frozen process's
keep-alive timeout and the simulation keep step)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import threading
from pathlib import Path

import numpy as np
import pytest

from landscape.server.states import State
from landscape.sim.controller import EnableState
from landscape.sim.kinematics import Kinematics

from holder_child import A, B
from reliability_support import RowLog, columns
from support import distance_to_line, start_server, wait_until


@pytest.fixture
def server():
    running = start_server(lockstep_pace=1.0)
    sessions = running.device.sessions
    sessions.keepalive_interval, sessions.keepalive_timeout = 0.15, 0.6
    yield running
    running.stop(grace=None)


def _detected(server, found: list, done: threading.Event) -> None:
    """Notes the simulated time at which the lock holder's loss is announced (alarm 101)."""
    with server.bus.subscribe() as events:
        for event in events:
            if event.event_id == "alarm" and event.detail.code == 101:
                found.append(server.device.feedback().time)
                done.set()
                return


@pytest.mark.parametrize("fault", [signal.SIGKILL, signal.SIGSTOP], ids=["killed", "frozen"])
def test_a_lock_holder_that_dies_or_freezes_mid_path_leaves_the_arm_at_rest_on_it(server,
                                                                                    fault):
    device = server.device
    child = subprocess.Popen([sys.executable, str(Path(__file__).parent / "holder_child.py"),
                              server.target], stdout=subprocess.PIPE, text=True)
    found, noticed = [], threading.Event()
    try:
        line = child.stdout.readline()
        assert line.startswith("moving"), line
        wait_until(lambda: device.motions.last_tag == ("line", "a"), timeout=60)
        log = RowLog(server.link.feedback)
        threading.Thread(target=_detected, args=(server, found, noticed), daemon=True).start()
        wait_until(lambda: device.feedback().time > 0, timeout=1)
        os.kill(child.pid, fault)
        assert noticed.wait(10)
        wait_until(lambda: device.state is State.UNLOCKED, timeout=10)
        rows = columns(log.close())
    finally:
        child.kill()
        if fault == signal.SIGSTOP:
            os.kill(child.pid, signal.SIGCONT)
        child.wait(10)
    detected = found[0]
    after = rows["t"] >= detected
    off = np.flatnonzero(after & (rows["enable"] == EnableState.DISABLED.value))
    assert off.size, "the drives never went off"
    print(f"{fault.name}: at rest with the drives off {rows['t'][off[0]] - detected:.3f} s "
          f"(simulated) after the loss was noticed")
    assert rows["t"][off[0]] - detected < 1.0
    assert np.max(np.abs(rows["qd"][off[0]:])) < 1e-3   # at rest, and stays so
    # Every cycle from the moment before the loss until rest: the tool tip on the line.
    kin = Kinematics(device.arm)
    tips = (kin.forward(rows["q"]) @ device.settings.tool_offset)[:, :3, 3]
    assert np.max(distance_to_line(tips, np.array(A), np.array(B))) < 1e-3
    assert not device.status().locked
