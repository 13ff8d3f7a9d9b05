"""A lock holder in a process of its own (for the tests that kill or freeze it): locks the
device at argv[1], activates, loads a straight path from A to B and runs it, says
"moving <command id>" on stdout, then waits to be killed."""
from __future__ import annotations

import math
import sys
import time

import grpc

from landscape.client import Session
from landscape.v1 import (control_pb2, device_service_pb2_grpc, motion_pb2, settings_pb2,
                          types_pb2)

A = (0.55, -0.25, 0.45)     # m, base frame, the tool pointing down
B = (0.55, 0.25, 0.45)


def main() -> None:
    channel = grpc.insecure_channel(sys.argv[1])
    session = Session(channel, "holder-child").open()
    session.lock()
    device = device_service_pb2_grpc.DeviceServiceStub(session.channel)
    device.Activate(control_pb2.ActivateRequest(), timeout=10)
    device.SetSpeed(settings_pb2.SetSpeedRequest(
        speed=0.15, attribute=types_pb2.SPEED_TYPE_LINEAR_SPEED), timeout=5)
    header = motion_pb2.PathHeader(path_name="line",
                                   frame=types_pb2.REFERENCE_FRAME_BASE_CARTESIAN_FRAME,
                                   motion_type=types_pb2.MOTION_TYPE_STRAIGHT_MOTION,
                                   offset_type=types_pb2.OFFSET_TYPE_ABSOLUTE_DATA)
    tags = [types_pb2.TagStruct(x=x, y=y, z=z, roll=math.pi, tag_name=name)
            for name, (x, y, z) in (("a", A), ("b", B))]
    device.PathLoad(iter([motion_pb2.PathLoadRequest(header=header, tags=tags)]), timeout=60)
    reply = device.PathMove(motion_pb2.PathMoveRequest(path_name="line"), timeout=10)
    print("moving", reply.ret_val.command_id, flush=True)
    while True:
        time.sleep(1)


if __name__ == "__main__":
    main()
