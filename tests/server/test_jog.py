"""Issue 10, seed 3.7.3: manual control and jogging on the real server, the simulated arm on
the lock-step clock paced at real time (the deadman counts controller time, the client wall
time): joint and Cartesian jogs, the joint ranges, the deadman, and what refuses a jog."""
from __future__ import annotations

import math
import queue
import threading
import time

import grpc
import numpy as np
import pytest

from landscape.server.planning.collision import clearance
from landscape.server.cycle.feedback import CMD, QD, SEQ
from landscape.server.cycle.jog_integrator import MANUAL_TIP_SPEED
from landscape.server.device.states import State
from landscape.v1 import motion_pb2, sensing_pb2, settings_pb2, types_pb2

from support import Arm, error_info, wait_until

# Jogs paced at real time, whose requests come from a thread of the test: on the kinematic
# backend simulated time keeps up with the wall clock exactly, so a client thread the machine's
# load holds up for the deadman's 200 ms trips it; the pybullet backend's (tests/conftest.py).
pytestmark = pytest.mark.physics

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
BASE = types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME
WORLD = types_pb2.REFERENCE_FRAME_WORLD_CARTESIAN_FRAME
TOOL = types_pb2.REFERENCE_FRAME_TOOL_FRAME
PERIOD = 0.02       # s between two jog requests, as a pendant sends them


@pytest.fixture
def arm(tmp_path, backend):
    a = Arm(tmp_path, pace=1.0, backend=backend)
    yield a
    a.close()


def _manual(arm, mode=sensing_pb2.MANUAL_CONTROL_TYPE_TEACHPENDANT) -> None:
    arm.device.ManualControl(sensing_pb2.ManualControlRequest(type=mode), timeout=5)


class Pendant:
    """A jog stream fed from a queue: `send` a request, `pause` (send nothing), `close`."""

    def __init__(self, arm, deadman_ms: int = 0):
        self.arm = arm
        self._requests: queue.Queue = queue.Queue()
        self._deadman_ms = deadman_ms
        self.replies = []
        self.error: grpc.RpcError | None = None
        self._call = arm.device.Jog(self._feed(), timeout=60)
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _feed(self):
        first = True
        while (request := self._requests.get()) is not None:
            if first:
                request.deadman_timeout_ms, first = self._deadman_ms, False
            yield request

    def _read(self):
        try:
            for reply in self._call:
                self.replies.append(reply)
        except grpc.RpcError as error:
            self.error = error

    def jog(self, frame, velocity, seconds: float, deadman: bool = True) -> None:
        """Requests every PERIOD for `seconds`."""
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self._requests.put(sensing_pb2.JogRequest(deadman=deadman, frame=frame,
                                                      velocity=velocity))
            time.sleep(PERIOD)

    def close(self) -> None:
        self._requests.put(None)
        self._reader.join(10)


def _rows(arm, first: int) -> np.ndarray:
    ring = arm.server.link.feedback
    rows = [ring.row(s) for s in range(max(first, ring.head - ring.rows + 1), ring.head + 1)]
    return np.array([r for r in rows if r is not None])


def test_jog_is_refused_without_manual_control_and_other_motions_under_it(arm):
    pendant = Pendant(arm)
    pendant.jog(JOINT, [10, 0, 0, 0, 0, 0], 0.05)
    pendant.close()
    assert pendant.error.code() is grpc.StatusCode.FAILED_PRECONDITION
    assert error_info(pendant.error).reason == "MANUAL_CONTROL"

    _manual(arm)
    assert arm.server.device.status().manual_control == "teachpendant"
    with pytest.raises(grpc.RpcError) as refused:
        arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
            frame=JOINT, values=[0.1, 0, 0, 0, 0, 0]), timeout=5)
    assert error_info(refused.value).reason == "MANUAL_CONTROL"
    _manual(arm, sensing_pb2.MANUAL_CONTROL_TYPE_OFF)
    reply = arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
        frame=JOINT, values=[0.5, 0, 0, 0, 0, 0], speed=5), timeout=5)

    pendant = Pendant(arm)            # a jog while a motion runs
    pendant.jog(JOINT, [10, 0, 0, 0, 0, 0], 0.05)
    pendant.close()
    assert pendant.error.code() is grpc.StatusCode.FAILED_PRECONDITION
    assert error_info(pendant.error).reason == "WRONG_STATE"
    arm.wait_command(reply.ret_val.command_id)


def test_a_joint_jog_moves_that_joint_at_its_jog_speed(arm):
    _manual(arm)
    start_q, first = arm.joints().copy(), arm.server.link.feedback.head
    pendant = Pendant(arm)
    pendant.jog(JOINT, [0, 0, 0, 0, 0, 50], 1.0)
    pendant.close()
    assert pendant.error is None and pendant.replies
    assert len(pendant.replies[-1].joint_position) == 6
    rows = _rows(arm, first)
    speed = 0.5 * arm.server.device.settings.joint_velocities[5]   # 50 % of the jog speed
    assert np.abs(rows[:, QD][:, 5]).max() == pytest.approx(speed, rel=0.01)
    moved = arm.joints() - start_q
    assert np.abs(moved[:5]).max() < 1e-4
    # For about the client's second of requests (the machine's load stretches it a little).
    assert 0.8 * speed < moved[5] < 1.5 * speed
    assert arm.server.device.state is State.RESTING
    done = [e for e in arm.history() if e.event_id == "command_done" and
            e.detail.command == "Jog"]
    assert len(done) == 1


def test_a_cartesian_jog_moves_the_tip_straight_within_the_manual_speed(arm):
    _manual(arm)
    start, first = arm.tool_tip(), arm.server.link.feedback.head
    pendant = Pendant(arm)
    pendant.jog(BASE, [0, 0, 100, 0, 0, 0], 0.6)     # up, as fast as allowed
    pendant.close()
    end = arm.tool_tip()
    moved = end[:3, 3] - start[:3, 3]
    assert moved[2] > 0.05
    assert np.linalg.norm(moved[:2]) < 1e-3 * moved[2]            # straight up
    assert np.allclose(end[:3, :3], start[:3, :3], atol=1e-4)     # the tool does not turn
    rows = _rows(arm, first)
    tips = arm.kin.forward(rows[:, CMD])[:, :3, 3]   # the setpoints: what the jog commands
    speeds = np.linalg.norm(np.diff(tips, axis=0), axis=1) / arm.server.link.cycle_time
    print(f"\nCartesian jog at 100 %: the tip at up to {speeds.max() * 1000:.1f} mm/s")
    assert speeds.max() <= MANUAL_TIP_SPEED * 1.001

    start = arm.tool_tip()
    pendant = Pendant(arm)
    pendant.jog(TOOL, [0, 0, 20, 0, 0, 0], 0.6)      # along the tool's z: it points down
    pendant.close()
    moved = arm.tool_tip()[:3, 3] - start[:3, 3]
    assert moved[2] < -0.01 and np.linalg.norm(moved[:2]) < 1e-3 * abs(moved[2])


def test_the_spaceball_jogs_along_the_world_frames_axes(arm):
    # The world frame turned a quarter about the base's z: its x is the base's y.
    arm.device.SetWorldCartesianFrame(settings_pb2.SetWorldCartesianFrameRequest(
        frame=types_pb2.Pose(yaw=math.pi / 2)), timeout=5)
    _manual(arm, sensing_pb2.MANUAL_CONTROL_TYPE_SPACEBALL)
    assert arm.server.device.status().manual_control == "spaceball"
    start = arm.tool_tip()
    pendant = Pendant(arm)
    pendant.jog(WORLD, [20, 0, 0, 0, 0, 0], 0.4)      # along the world's x
    pendant.close()
    assert pendant.error is None and pendant.replies
    end = arm.tool_tip()
    moved = end[:3, 3] - start[:3, 3]                 # base axes
    assert moved[1] > 0.01
    assert np.linalg.norm(moved[[0, 2]]) < 1e-3 * moved[1]
    assert np.allclose(end[:3, :3], start[:3, :3], atol=1e-4)
    world = pendant.replies[-1].world_position        # the replies say it in world axes
    assert (world.x, world.y) == pytest.approx((end[1, 3], -end[0, 3]), abs=0.01)  # (braking)


def test_a_jog_stops_before_the_end_of_a_joint_range(arm):
    _manual(arm)
    pendant = Pendant(arm)
    # Joint 6 towards its 270 degrees (it turns the flange, so no obstacle comes nearer;
    # joint 5 would meet the collision margin of the wrist's shapes first, at about 110).
    pendant.jog(JOINT, [0, 0, 0, 0, 0, 100], 2.5)
    pendant.close()
    upper = arm.server.device.arm.upper[5]
    q6 = arm.joints()[5]
    assert upper - 0.01 < q6 < upper
    assert arm.server.device.state is State.RESTING    # no controller fault on the way


def test_silence_stops_the_arm_at_full_deceleration_once_the_deadman_runs_out(arm):
    _manual(arm)
    pendant = Pendant(arm)
    pendant.jog(JOINT, [100, 0, 0, 0, 0, 0], 0.5)    # joint 1, then the client falls silent
    last = arm.server.link.feedback.head
    wait_until(lambda: pendant.error is not None, timeout=5)
    assert pendant.error.code() is grpc.StatusCode.ABORTED
    assert "deadman" in pendant.error.details()
    # The stream ends as the braking starts; its jerk-limited ramp may outlast it.
    wait_until(lambda: np.abs(arm.server.device.feedback().velocity).max() <= 1e-6, timeout=5)
    rows = _rows(arm, last - 50)
    moving = np.abs(rows[:, QD]).max(axis=1) > 1e-6
    stopped_at = rows[np.nonzero(moving)[0][-1] + 1, SEQ]
    dt = arm.server.link.cycle_time
    took = (stopped_at - last) * dt
    # Joint 1's setpoints: the jog's speed until the deadman ran out, then braking to rest at
    # the arm's full deceleration (counted in cycles; the whole figure is bench_faults.py's).
    speed = np.abs(np.diff(rows[:, CMD][:, 0])) / dt
    cruising = int(np.flatnonzero(speed >= speed[0] - 1e-9)[-1])
    rest = cruising + int(np.argmax(speed[cruising:] < 1e-9))
    # The arm's full deceleration, ramped up and down at its jerk limit (issue 30): v/a + a/j.
    a, j = arm.server.device.arm.max_acceleration[0], arm.server.device.arm.max_jerk[0]
    braking = speed[0] / a + a / j
    print(f"\ndeadman: stopped {took * 1000:.0f} ms after the last request (timeout 200 ms, "
          f"braking {braking * 1000:.0f} ms)")
    assert speed[0] > 0.1 and (rest - cruising) * dt <= braking + 2 * dt
    pendant.close()
    assert arm.server.device.state is State.RESTING


def test_releasing_the_deadman_holds_the_arm_until_it_is_pressed_again(arm):
    _manual(arm)
    pendant = Pendant(arm)
    pendant.jog(JOINT, [0, 0, 0, 0, 0, 50], 0.3)
    pendant.jog(JOINT, [0, 0, 0, 0, 0, 50], 0.3, deadman=False)
    held = arm.joints()[5]
    pendant.jog(JOINT, [0, 0, 0, 0, 0, 50], 0.3, deadman=False)
    assert arm.joints()[5] == pytest.approx(held, abs=1e-6)
    pendant.jog(JOINT, [0, 0, 0, 0, 0, 50], 0.3)
    assert arm.joints()[5] > held + 0.1
    pendant.close()
    assert pendant.error is None


def test_stop_motion_ends_a_jog(arm):
    _manual(arm)
    pendant = Pendant(arm)
    pendant.jog(JOINT, [0, 0, 0, 0, 0, 50], 0.2)
    arm.device.StopMotion(motion_pb2.StopMotionRequest(), timeout=5)
    pendant.close()
    assert pendant.error.code() is grpc.StatusCode.ABORTED
    assert arm.server.device.state is State.RESTING


def test_a_jog_toward_the_table_slows_and_stops_at_the_margin_and_may_leave(arm):
    """Issue 11: jog scaled down near an obstacle, stopped at the margin, free to go away."""
    arm.move_down_to(0.55, 0.3, 0.45)                # the flange over the table, clear of parts
    _manual(arm)
    scene = arm.server.device.collisions
    first = arm.server.link.feedback.head
    pendant = Pendant(arm)
    pendant.jog(BASE, [0, 0, -100, 0, 0, 0], 3.0)   # straight down, as fast as allowed
    rows = _rows(arm, first)
    near = clearance(scene.model(), rows[-1, CMD])
    tips = arm.kin.forward(rows[:, CMD])[:, :3, 3]
    speeds = np.linalg.norm(np.diff(tips, axis=0), axis=1) / arm.server.link.cycle_time
    print(f"\njog down onto the table: stopped {near.distance * 1000:.2f} mm from "
          f"{' and '.join(near.bodies)}; top speed {speeds.max() * 1000:.0f} mm/s")
    assert "table" in near.bodies
    assert scene.margin - 0.0005 <= near.distance <= scene.margin + 0.002
    assert speeds[-10:].max() < 1e-3                # at rest, the deadman still pressed
    assert speeds.max() > 0.2                       # it jogged at speed on the way
    assert "margin" in pendant.replies[-1].ret_val.ret_msg
    assert "table" in pendant.replies[-1].ret_val.ret_msg
    assert arm.server.device.state is State.MOVING   # still jogging: held, not ended

    before = arm.tool_tip()[:3, 3]
    pendant.jog(BASE, [0, 0, 50, 0, 0, 0], 0.4)      # away: free at once
    pendant.close()
    assert arm.tool_tip()[2, 3] > before[2] + 0.02
    assert clearance(scene.model(), arm.joints()).distance > scene.margin + 0.02
