"""StopMotion while the arm moves (spec VII): Immediate stops at once and powers down, Fast
stops on the path and powers down, Normal stops on the path with the drives on. Against the
real gateway and device server; what the device did is read from its own event stream."""
from __future__ import annotations

import time

import numpy as np
import pytest

from landscape.server.device.states import State

from support import bus_history, distance_to_line, wait_until

from crcl_support import RawClient, command, field, pose
from test_gateway import MOVE, point

START, GOAL = (0.5, 0.3, 0.5), (0.5, -0.3, 0.5)


@pytest.fixture
def moving(gateway, server):
    """A session whose slow straight MoveTo (CommandID 3) has the arm moving."""
    client = RawClient(gateway.port)
    client.run("InitCanon", 1)
    client.run("MoveTo", 2, MOVE.format("true") + pose(*START))
    client.run("SetTransSpeed", 10, '<TransSpeed xsi:type="TransSpeedRelativeType">'
                                    '<Fraction>0.05</Fraction></TransSpeed>')
    client.send(command("MoveTo", 3, MOVE.format("true") + pose(*GOAL)))
    wait_until(lambda: server.device.state is State.MOVING, timeout=10)
    time.sleep(0.2)
    yield client
    client.close()


def _transitions_since(server, sequence: int) -> list[tuple[str, str, str]]:
    return [(e.detail.from_state, e.detail.to_state, e.detail.reason)
            for e in bus_history(server)
            if e.sequence > sequence and e.event_id == "state_changed"]


@pytest.mark.parametrize("condition, drives_after", [
    ("Immediate", State.INACTIVE), ("Fast", State.INACTIVE), ("Normal", State.RESTING)])
def test_stop_motion_while_moving(server, moving, condition, drives_after):
    before = bus_history(server)[-1].sequence
    stopped = moving.run("StopMotion", 4, f"<StopCondition>{condition}</StopCondition>")
    assert field(stopped, "CommandState") == "CRCL_Done", stopped
    assert server.device.state is drives_after
    preempted = moving.status()
    at = np.array(point(preempted))
    # stopped between start and goal, on the straight line (a controlled stop along the path)
    assert np.linalg.norm(at - GOAL) > 0.05
    assert distance_to_line(at[None], np.array(START), np.array(GOAL))[0] < 1e-3
    changes = _transitions_since(server, before)
    to_states = [to for _, to, _ in changes]
    if condition == "Immediate":
        # straight to the device's power-down (its brake, then drives off): no controlled stop
        # (StopMotion: Paused) asked ahead of it
        assert "paused" not in to_states and to_states[-1] == "inactive", changes
        assert changes[-1][2] == "deactivated", changes
    elif condition == "Fast":
        assert to_states[0] == "paused" and to_states[-1] == "inactive", changes
    else:
        assert "inactive" not in to_states and to_states[-1] == "resting", changes
    # the next motion command turns the drives back on and moves
    done = moving.run("MoveTo", 5, MOVE.format("false") + pose(0.5, 0.0, 0.6))
    assert field(done, "CommandState") == "CRCL_Done", done


def test_a_stop_does_not_wait_behind_commands_queued_before_it(server, moving):
    """Queued commands are dropped: the stop is the next thing the device hears."""
    moving.send(command("Dwell", 4, "<DwellTime>30</DwellTime>") +
                command("Dwell", 5, "<DwellTime>30</DwellTime>") +
                command("StopMotion", 6, "<StopCondition>Immediate</StopCondition>"))
    status = moving.wait_done(6, timeout=10)
    assert field(status, "CommandState") == "CRCL_Done", status
    assert server.device.state is State.INACTIVE
