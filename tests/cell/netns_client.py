"""The two clients of the multi-host test, each run inside a network namespace
(`ip netns exec NS python netns_client.py MODE TARGET CA TOKEN_FILE`); they report on stdout,
one JSON object a line.

supervise: lock, activate, start a slow move, say so; then, on "relock" from stdin, lock
    again on a fresh channel and session (the old one may be dead), say so, release and exit.
watch: GetDeviceState and the joints every 20 ms, each with time.monotonic() (the same clock
    in every process of the machine), until killed.
"""
from __future__ import annotations

import json
import sys
import time

import grpc

from landscape.client import ClientTLS, Session, open_channel, read_token
from landscape.v1 import (control_pb2, device_service_pb2_grpc, motion_pb2, settings_pb2,
                          types_pb2)

FAR_GOAL = [2.5, -0.3, 1.9, 0.5, 1.2, -0.5]   # rad; at 5 % speed, several seconds away


def say(**fields) -> None:
    print(json.dumps({"t": time.monotonic(), **fields}), flush=True)


def supervise(target: str, tls: ClientTLS, token: str) -> None:
    channel = open_channel(target, tls, token)
    session = Session(channel, "remote-supervisor").open()
    session.lock()
    device = device_service_pb2_grpc.DeviceServiceStub(session.channel)
    device.Activate(control_pb2.ActivateRequest(), timeout=30)
    device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
        point_name="far", frame=types_pb2.REFERENCE_FRAME_JOINT_FRAME, values=FAR_GOAL,
        speed=5.0), timeout=30)
    say(event="moving", goal=FAR_GOAL)
    for line in sys.stdin:
        if line.strip() == "relock":
            with open_channel(target, tls, token) as fresh, Session(fresh, "again") as again:
                again.lock()
                say(event="relocked")
                device_service_pb2_grpc.DeviceServiceStub(again.channel).Release(
                    control_pb2.ReleaseRequest(), timeout=30)
            break
    session.close()


def watch(target: str, tls: ClientTLS, token: str) -> None:
    with open_channel(target, tls, token) as channel:
        device = device_service_pb2_grpc.DeviceServiceStub(channel)
        while True:
            try:
                state = device.GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=5)
                joints = device.GetRobotPosition(settings_pb2.GetRobotPositionRequest(),
                                                 timeout=5).joint_position
                say(state=types_pb2.DeviceState.Name(state.state), locked=state.locked,
                    joints=list(joints))
            except grpc.RpcError as error:
                say(error=error.code().name)
            time.sleep(0.02)


def main() -> None:
    mode, target, ca, token_file = sys.argv[1:5]
    {"supervise": supervise, "watch": watch}[mode](target, ClientTLS(ca=ca),
                                                  read_token(token_file))


if __name__ == "__main__":
    main()
