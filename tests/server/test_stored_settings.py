"""Issue 9.3: the set commands' settings survive a restart, and can be reset to defaults."""
from __future__ import annotations

import math

import grpc
import numpy as np

from landscape.v1 import settings_pb2, types_pb2

from support import locked_session, start_server, stubs

MM_DEG = dict(linear_units=types_pb2.LINEAR_UNIT_MILLIMETERS,
              angular_units=types_pb2.ANGULAR_UNIT_DEGREES)


def _read(device) -> tuple:
    return (device.GetUnits(settings_pb2.GetUnitsRequest()),
            device.GetVelocities(settings_pb2.GetVelocitiesRequest()),
            device.GetAccelerations(settings_pb2.GetAccelerationsRequest()),
            device.GetToolOffsets(settings_pb2.GetToolOffsetsRequest()))


def test_settings_read_back_the_same_after_a_restart_and_reset_restores_defaults(tmp_path):
    file = str(tmp_path / "paths.sqlite3")
    server = start_server(paths_file=file)
    holder = locked_session(server)
    try:
        device, _, _ = stubs(holder.channel)
        device.SetUnits(settings_pb2.SetUnitsRequest(**MM_DEG))
        device.SetSpeed(settings_pb2.SetSpeedRequest(
            speed=40, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED))
        device.SetSpeed(settings_pb2.SetSpeedRequest(
            speed=300, attribute=types_pb2.SPEED_TYPE_LINEAR_SPEED))      # mm/s
        device.SetAcceleration(settings_pb2.SetAccelerationRequest(
            accel=70, attribute=types_pb2.ACCEL_TYPE_PERCENT_ACCEL))
        device.SetToolOffset(settings_pb2.SetToolOffsetRequest(
            offset=types_pb2.Pose(z=150, roll=10)))                        # mm, degrees
        device.SetWorldCartesianFrame(settings_pb2.SetWorldCartesianFrameRequest(
            frame=types_pb2.Pose(x=500, yaw=90)))
        before = _read(device)
        world = server.device.settings.world_frame.copy()
    finally:
        holder.close()
        server.stop(grace=None)

    again = start_server(paths_file=file)
    try:
        device, _, _ = stubs(grpc.insecure_channel(again.target))
        assert _read(device) == before
        assert np.allclose(again.device.settings.world_frame, world)
        assert before[3].offset.z == 150 and math.isclose(before[1].world_linear_velocity, 300)
    finally:
        again.stop(grace=None)

    fresh = start_server(paths_file=file, reset_settings=True)
    try:
        settings = fresh.device.settings
        assert (settings.speed_percent, settings.accel_percent) == (25.0, 50.0)
        assert np.allclose(settings.tool_offset, np.eye(4))
        assert settings.units.linear.name == "METERS"
    finally:
        fresh.stop(grace=None)
