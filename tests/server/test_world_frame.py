"""GetWorldCartesianFrame (an extension of seed 3.3.1): the world frame SetWorldCartesianFrame
set, read back by any client in the device's units (issue 27 item 2: a client can see what the
device's frame is, whoever set it)."""
from __future__ import annotations

import math

import grpc
import pytest

from landscape.v1 import settings_pb2, types_pb2

from support import locked_session, stubs


def _frame(channel) -> tuple[tuple[float, ...], types_pb2.Units]:
    device, _, _ = stubs(channel)
    reply = device.GetWorldCartesianFrame(settings_pb2.GetWorldCartesianFrameRequest(), timeout=5)
    f = reply.frame
    return (f.x, f.y, f.z, f.roll, f.pitch, f.yaw), reply.units


def test_the_world_frame_is_read_back_by_any_client_in_the_devices_units(server):
    with grpc.insecure_channel(server.target) as reader:     # no session, no lock
        frame, units = _frame(reader)
        assert frame == (0.0,) * 6                             # the base, until set
        holder = locked_session(server, "holder")
        try:
            device, _, _ = stubs(holder.channel)
            device.SetUnits(settings_pb2.SetUnitsRequest(
                linear_units=types_pb2.LINEAR_UNIT_MILLIMETERS,
                angular_units=types_pb2.ANGULAR_UNIT_DEGREES))
            device.SetWorldCartesianFrame(settings_pb2.SetWorldCartesianFrameRequest(
                frame=types_pb2.Pose(x=1000.0, y=-250.0, yaw=90.0)))
            frame, units = _frame(reader)
            assert frame == pytest.approx((1000.0, -250.0, 0.0, 0.0, 0.0, 90.0), abs=1e-9)
            assert (units.linear, units.angular) == (types_pb2.LINEAR_UNIT_MILLIMETERS,
                                                     types_pb2.ANGULAR_UNIT_DEGREES)
            device.SetUnits(settings_pb2.SetUnitsRequest(
                linear_units=types_pb2.LINEAR_UNIT_METERS,
                angular_units=types_pb2.ANGULAR_UNIT_RADIANS))
            frame, _ = _frame(reader)
            assert frame == pytest.approx((1.0, -0.25, 0.0, 0.0, 0.0, math.pi / 2), abs=1e-12)
        finally:
            holder.close()


def test_the_client_core_reads_it(server):
    from landscape.client import Robot
    with Robot(server.target, "reader") as robot:
        f = robot.get_world_cartesian_frame().frame
        assert (f.x, f.y, f.z, f.roll, f.pitch, f.yaw) == (0.0,) * 6
