"""Stop and resume ramps through gRPC keep every joint within its acceleration limit, measured
as the second difference of the commanded positions (recorder, lock-step clock)."""
from __future__ import annotations

import numpy as np

from landscape.server.device.states import State
from landscape.v1 import motion_pb2, settings_pb2, types_pb2

from support import Arm, wait_until

JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
PERCENT_SPEED = types_pb2.SPEED_TYPE_PERCENT_SPEED
PERCENT_ACCEL = types_pb2.ACCEL_TYPE_PERCENT_ACCEL
START = [-1.2, -0.2, 1.9, 0.4, 1.1, -0.5]
GOAL = [1.3, 0.3, 1.4, -0.8, 0.7, 1.2]
DT = 0.004


def wait_simulated(arm, seconds: float) -> None:
    t0 = arm.server.device.feedback().time
    wait_until(lambda: arm.server.device.feedback().time >= t0 + seconds, timeout=20)


def test_stop_and_resume_at_full_speed_keep_the_commanded_acceleration_within_the_limit(tmp_path):
    """Issue 8 item 6: at 100 % speed and acceleration, StopMotion 0.1 s (simulated) after the
    start and ResumeMotion 0.1 s later; every cycle within the limit (relative 1e-6)."""
    arm = Arm(tmp_path, pace=1.0)
    try:
        arm.device.SetSpeed(settings_pb2.SetSpeedRequest(attribute=PERCENT_SPEED, speed=100))
        arm.device.SetAcceleration(settings_pb2.SetAccelerationRequest(
            attribute=PERCENT_ACCEL, accel=100))
        reply = arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(frame=JOINT, values=START))
        arm.wait_command(reply.ret_val.command_id)
        wait_until(lambda: arm.server.device.state is State.RESTING, timeout=20)
        arm.record_start()
        reply = arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(frame=JOINT, values=GOAL))
        wait_simulated(arm, 0.1)
        arm.device.StopMotion(motion_pb2.StopMotionRequest())
        wait_simulated(arm, 0.1)
        arm.device.ResumeMotion(motion_pb2.ResumeMotionRequest())
        events = arm.wait_command(reply.ret_val.command_id)
        assert [e.event_id for e in events] == ["command_started", "command_paused",
                                                "command_resumed", "command_done"]
        _, data = arm.recorded_tips()
        limit = arm.server.device.settings.joint_accelerations
        accel = np.abs(np.diff(data["cmd_pos"], 2, axis=0)) / DT**2
        ratio = (accel / limit).max(axis=0)
        print(f"peak commanded acceleration / limit per joint: {np.round(ratio, 4)}")
        assert np.all(ratio <= 1 + 1e-6), ratio
        assert np.max(np.abs(data["cmd_pos"][-1] - GOAL)) < 1e-9
    finally:
        arm.close()
