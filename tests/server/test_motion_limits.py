"""The set Cartesian speeds and accelerations (seed 3.2.1) as a straight or arc move meets them,
and a move's or a path run's own (MoveRates, an extension: for that motion alone, the device's
settings unchanged; issue 27 item 6), through gRPC on the simulated arm (lock-step clock),
measured on the recorder's commanded joint positions turned into tool-tip poses."""
from __future__ import annotations

import math

import grpc
import numpy as np
import pytest

from landscape.client import Frame, TagPoint
from landscape.v1 import motion_pb2, settings_pb2, types_pb2

from support import error_info


BASE = types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME
STRAIGHT = types_pb2.MOTION_TYPE_STRAIGHT_MOTION
DT = 0.004


def set_speed(arm, attribute, value):
    arm.device.SetSpeed(settings_pb2.SetSpeedRequest(speed=value, attribute=attribute))


def set_accel(arm, attribute, value):
    arm.device.SetAcceleration(settings_pb2.SetAccelerationRequest(accel=value,
                                                                   attribute=attribute))


def recorded_move(arm, request) -> np.ndarray:
    """Runs a move with the recorder on; the commanded tip poses (k, 4, 4), one per cycle."""
    arm.record_start()
    reply = request()
    assert arm.wait_command(reply.ret_val.command_id)[-1].event_id == "command_done"
    _, data = arm.recorded_tips()
    return arm.kin.forward(data["cmd_pos"])


def linear_profile(poses) -> tuple[np.ndarray, np.ndarray]:
    p = poses[:, :3, 3]
    speed = np.linalg.norm(np.diff(p, axis=0), axis=1) / DT
    accel = np.linalg.norm(p[2:] - 2 * p[1:-1] + p[:-2], axis=1) / DT**2
    return speed, accel


def line(arm, dy: float, **fields):
    return lambda: arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
        frame=BASE, values=[0.0, dy, 0.0, 0, 0, 0], motion_type=STRAIGHT, **fields))


def test_linear_speed_is_an_absolute_cap_not_scaled_by_the_percent(arm):
    """Issue 9 item 1: SetSpeed(60, PERCENT), SetSpeed(0.2, LINEAR_SPEED): a 0.4 m line peaks
    at 0.2 m/s (it was 0.12 m/s: the linear speed times the percent)."""
    set_speed(arm, types_pb2.SPEED_TYPE_PERCENT_SPEED, 60)
    set_speed(arm, types_pb2.SPEED_TYPE_LINEAR_SPEED, 0.2)
    speed, _ = linear_profile(recorded_move(arm, line(arm, 0.4)))
    print(f"peak tip speed {speed.max():.5f} m/s")
    assert 0.2 * 0.99 <= speed.max() <= 0.2 * (1 + 1e-6)
    reported = arm.device.GetVelocities(settings_pb2.GetVelocitiesRequest())
    assert reported.world_linear_velocity == pytest.approx(0.2)


def test_linear_acceleration_caps_the_tip_acceleration_and_is_reached(arm):
    set_speed(arm, types_pb2.SPEED_TYPE_PERCENT_SPEED, 60)
    set_accel(arm, types_pb2.ACCEL_TYPE_PERCENT_ACCEL, 100)
    set_accel(arm, types_pb2.ACCEL_TYPE_LINEAR_ACCEL, 0.5)
    speed, accel = linear_profile(recorded_move(arm, line(arm, -0.4)))
    print(f"peak tip acceleration {accel.max():.5f} m/s^2, speed {speed.max():.4f} m/s")
    assert 0.5 * 0.97 <= accel.max() <= 0.5 * (1 + 1e-6)
    # A triangle of 0.4 m at 0.5 m/s^2 peaks at sqrt(a d) = 0.447 m/s.
    assert speed.max() == pytest.approx(math.sqrt(0.5 * 0.4), rel=0.03)


def test_an_arc_keeps_the_linear_acceleration_with_its_centripetal_part(arm):
    set_speed(arm, types_pb2.SPEED_TYPE_PERCENT_SPEED, 100)
    set_accel(arm, types_pb2.ACCEL_TYPE_PERCENT_ACCEL, 100)
    set_accel(arm, types_pb2.ACCEL_TYPE_LINEAR_ACCEL, 1.0)
    p0 = arm.tip()[:3, 3]
    rpy = [math.pi, 0.0, math.pi]
    via, goal = p0 + [0.1, 0.1, 0.0], p0 + [0.2, 0.0, 0.0]
    poses = recorded_move(arm, lambda: arm.device.MoveArc(motion_pb2.MoveArcRequest(
        frame=BASE, offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA, arc_value=[*via, *rpy],
        goal_value=[*goal, *rpy])))
    speed, accel = linear_profile(poses)
    print(f"arc: peak tip acceleration {accel.max():.5f} m/s^2, speed {speed.max():.4f} m/s")
    assert 0.97 <= accel.max() <= 1.0 * (1 + 1e-6)
    assert speed.max() <= math.sqrt(1.0 * 0.1) * (1 + 1e-6)   # centripetal v^2 / r <= a


def test_angular_speed_and_acceleration_cap_a_reorientation(arm):
    set_speed(arm, types_pb2.SPEED_TYPE_PERCENT_SPEED, 50)
    set_speed(arm, types_pb2.SPEED_TYPE_ANGULAR_SPEED, 0.4)
    set_accel(arm, types_pb2.ACCEL_TYPE_ANGULAR_ACCEL, 1.5)
    poses = recorded_move(arm, lambda: arm.device.MoveRelative(motion_pb2.MoveRelativeRequest(
        frame=BASE, values=[0, 0, 0, 0, 0, 0.8], motion_type=STRAIGHT)))
    R = poses[:, :3, :3]
    chord = np.linalg.norm(R[1:] - R[:-1], axis=(1, 2))
    rate = 2 * np.arcsin(np.minimum(1, chord / (2 * math.sqrt(2)))) / DT
    accel = np.abs(np.diff(rate)) / DT      # about one fixed axis: the rate's change
    print(f"peak tool rate {rate.max():.5f} rad/s, acceleration {accel.max():.4f} rad/s^2")
    assert 0.4 * 0.99 <= rate.max() <= 0.4 * (1 + 1e-6)
    assert 1.5 * 0.95 <= accel.max() <= 1.5 * (1 + 1e-4)


# ---- MoveRates: a motion's own --------------------------------------------------------------

def _settings(arm) -> tuple:
    speeds = arm.device.GetVelocities(settings_pb2.GetVelocitiesRequest())
    accels = arm.device.GetAccelerations(settings_pb2.GetAccelerationsRequest())
    return (speeds.percent_velocity, speeds.world_linear_velocity, speeds.world_angular_velocity,
            accels.percent_accel, accels.world_linear_accel, accels.world_angular_accel)


def test_a_moves_own_rates_hold_it_and_leave_the_devices_settings(arm):
    set_speed(arm, types_pb2.SPEED_TYPE_PERCENT_SPEED, 60)
    before = _settings(arm)
    speed, accel = linear_profile(recorded_move(arm, line(
        arm, 0.4, rates=motion_pb2.MoveRates(linear_speed=0.15, accel_percent=100,
                                             linear_accel=0.5))))
    print(f"own rates: peak {speed.max():.4f} m/s, {accel.max():.4f} m/s^2")
    assert 0.15 * 0.99 <= speed.max() <= 0.15 * (1 + 1e-6)
    assert accel.max() <= 0.5 * (1 + 1e-6)
    assert _settings(arm) == before
    speed, _ = linear_profile(recorded_move(arm, line(arm, -0.4)))   # the device's again
    assert speed.max() > 0.3


def test_a_rate_out_of_its_bounds_is_refused_naming_it_and_nothing_moves(arm):
    joints = arm.joints().copy()
    with pytest.raises(grpc.RpcError) as refused:
        arm.device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            frame=BASE, values=[0.5, 0.1, 0.6, 3.14159, 0, 0], motion_type=STRAIGHT,
            rates=motion_pb2.MoveRates(angular_speed=1e3)))
    assert refused.value.code() is grpc.StatusCode.OUT_OF_RANGE
    assert "angular speed must be at least" in refused.value.details()
    assert error_info(refused.value).metadata["field"] == "angular_speed"
    assert arm.joints() == pytest.approx(joints, abs=1e-9)


def test_a_path_run_carries_its_own_rates(arm):
    set_speed(arm, types_pb2.SPEED_TYPE_PERCENT_SPEED, 60)
    before = _settings(arm)
    tip = arm.tip()[:3, 3]
    points = [[*tip, 3.14159265, 0.0, 3.14159265], [tip[0], tip[1] + 0.4, tip[2],
                                                    3.14159265, 0.0, 3.14159265]]
    header = motion_pb2.PathHeader(path_name="slow", frame=BASE, motion_type=STRAIGHT,
                                   offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA,
                                   number_of_points=2)
    arm.device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header, tags=[
        TagPoint(p).to_pb(Frame.BASE) for p in points])]))
    speed, _ = linear_profile(recorded_move(arm, lambda: arm.device.PathMove(
        motion_pb2.PathMoveRequest(path_name="slow",
                                   rates=motion_pb2.MoveRates(linear_speed=0.1)))))
    assert 0.1 * 0.99 <= speed.max() <= 0.1 * (1 + 1e-6)
    assert _settings(arm) == before
