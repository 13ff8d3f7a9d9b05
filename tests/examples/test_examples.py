"""The numbered examples run as a newcomer runs them, against real device servers."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from landscape.client import Robot
from landscape.server.device.states import State

from support import start_server

EXAMPLES = Path(__file__).resolve().parents[2] / "examples"


def run_example(name: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, str(EXAMPLES / name), *args], capture_output=True,
                          text=True, timeout=180)


def test_first_steps_moves_waits_reads_and_releases(server):
    done = run_example("01_first_steps.py", "--target", server.target)
    assert done.returncode == 0, done.stderr
    assert "done: command_done" in done.stdout and "joints: [0.5, 0.0, 1.57" in done.stdout
    assert done.stdout.rstrip().endswith("released; device state: UNLOCKED")
    assert server.device.state is State.UNLOCKED


def test_pick_and_place_moves_the_block_to_the_place_zone_and_returns_the_gripper(server):
    before = _bodies(server)
    assert before["block_1"].pose.x == pytest.approx(0.5, abs=0.005)   # in the pick zone
    done = run_example("02_pick_and_place.py", "--target", server.target)
    assert done.returncode == 0, done.stderr
    assert "block_1 moved to the place zone" in done.stdout
    after = _bodies(server)   # where the device knows them to be now
    block = after["block_1"]
    assert not block.attached_to
    assert (block.pose.x, block.pose.y) == pytest.approx((0.73, -0.15), abs=0.01)
    assert block.pose.z == pytest.approx(before["block_1"].pose.z, abs=0.01)   # on the table
    gripper = after["gripper"]
    slot = before["gripper"].pose
    assert not gripper.attached_to   # back in its slot
    assert (gripper.pose.x, gripper.pose.y, gripper.pose.z) == pytest.approx(
        (slot.x, slot.y, slot.z), abs=1e-3)
    assert server.device.state is State.UNLOCKED


def _bodies(server) -> dict:
    with Robot(server.target, "test-looker") as robot:
        return {body.name: body for body in robot.get_cell_description().bodies}


def test_teach_and_replay_saves_a_path_file_and_replays_its_tags(server, tmp_path):
    path_file = tmp_path / "taught.json"
    done = run_example("03_teach_and_replay.py", "--target", server.target,
                       "--file", str(path_file), "--cycles", "2")
    assert done.returncode == 0, done.stderr
    saved = json.loads(path_file.read_text())
    names = [point["tag_name"] for point in saved["points"]]
    assert names == ["approach", "left", "right", "home"]
    assert done.stdout.count("  reached ") == 2 * len(names)


@pytest.fixture
def second_server():
    running = start_server()
    yield running
    running.stop(grace=None)


def test_two_robots_move_at_once(server, second_server):
    done = run_example("04_two_robots.py", "--targets", server.target, second_server.target)
    assert done.returncode == 0, done.stderr
    for name in ("left-robot", "right-robot"):
        assert done.stdout.count(f"{name}: command_done") == 4
    assert server.device.state is State.UNLOCKED and second_server.device.state is State.UNLOCKED
    assert server.device.feedback().position[0] == pytest.approx(-0.6, abs=1e-4)
    assert second_server.device.feedback().position[0] == pytest.approx(0.6, abs=1e-4)
