"""Several arms in one cell: the launcher's cell file places each arm's base in the shared
cell's frame, the device server is told where (--placement, --shared-cell) and says so in
GetCellDescription.world_in_cell; real servers on loopback."""
from __future__ import annotations

import math
import subprocess
import sys

import grpc
import numpy as np

from landscape.robot.units import pose_matrix
from landscape.v1 import control_pb2, device_service_pb2_grpc

from support import cell_file, spawned_server, start_server


def describe(target):
    device = device_service_pb2_grpc.DeviceServiceStub(grpc.insecure_channel(target))
    return device.GetCellDescription(control_pb2.GetCellDescriptionRequest(), timeout=10)


def matrix(pose) -> np.ndarray:
    return pose_matrix((pose.x, pose.y, pose.z), (pose.roll, pose.pitch, pose.yaw))


def test_world_in_cell_puts_the_base_where_the_cell_places_it(tmp_path):
    # A world whose base is not at its origin: the placement is the base's, not the world's.
    cell = cell_file(tmp_path, {"base_xyz = [0.0, 0.0, 0.0]": "base_xyz = [0.3, -0.2, 0.1]"})
    placement = (1.0, 2.5, 0.0, 0.0, 0.0, math.radians(90))
    server = start_server(cell=cell, placement=placement, shared_cell="lan")
    try:
        reply = describe(server.target)
    finally:
        server.stop(grace=None)
    assert reply.HasField("world_in_cell") and reply.shared_cell == "lan"
    base_in_cell = matrix(reply.world_in_cell) @ matrix(reply.base)
    assert np.allclose(base_in_cell, pose_matrix(placement[:3], placement[3:]), atol=1e-9)


def test_an_arm_placed_nowhere_says_so(tmp_path):
    server = start_server()
    try:
        reply = describe(server.target)
    finally:
        server.stop(grace=None)
    assert not reply.HasField("world_in_cell") and reply.shared_cell == ""


def test_the_command_line_takes_the_placement_in_metres_and_degrees(tmp_path):
    with spawned_server("--placement=-1.5,0,0.25,0,0,180", "--shared-cell=lan",
                        "--paths", str(tmp_path / "paths.sqlite3")) as target:
        reply = describe(target)
    assert np.allclose(matrix(reply.world_in_cell),
                       pose_matrix((-1.5, 0.0, 0.25), (0.0, 0.0, math.pi)), atol=1e-9)
    refused = subprocess.run([sys.executable, "-m", "landscape.server", "--placement", "1,2,x"],
                             capture_output=True, text=True, timeout=60)
    assert refused.returncode == 2 and "--placement takes six numbers" in refused.stderr
