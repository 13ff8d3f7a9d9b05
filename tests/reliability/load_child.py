"""The crowd around a lock holder (for the load test): 32 clients hammering reads, each now
and then trying a command of its own, and 8 subscribers of the event stream, against the
device at argv[1]. Says "ready" once all are at work; on "stop" (stdin) prints one JSON line:
reads done, commands accepted (should be none), commands refused, and per subscriber the
(command id, tag name) of every tag event it read, in order, and whether it lost events."""
from __future__ import annotations

import asyncio
import json
import sys

import grpc

from landscape.client import AsyncSession
from landscape.v1 import (control_pb2, device_service_pb2_grpc, event_service_pb2,
                          event_service_pb2_grpc, motion_pb2, settings_pb2, types_pb2)

CLIENTS, SUBSCRIBERS = 32, 8
JOINT = types_pb2.REFERENCE_FRAME_JOINT_FRAME
BOGUS = (("landscape-lease", "not-the-lease"),)


def attempts(device):
    """Commands others may not give while the device is locked (no lease, a wrong lease)."""
    return [
        lambda md: device.SetSpeed(settings_pb2.SetSpeedRequest(
            speed=5, attribute=types_pb2.SPEED_TYPE_PERCENT_SPEED), metadata=md),
        lambda md: device.MoveAbsolute(motion_pb2.MoveAbsoluteRequest(
            frame=JOINT, values=[0, 0, 1.5708, 0, 1.5708, 0]), metadata=md),
        lambda md: device.StopMotion(motion_pb2.StopMotionRequest(), metadata=md),
        lambda md: device.AbortMotion(motion_pb2.AbortMotionRequest(), metadata=md),
        lambda md: device.Deactivate(control_pb2.DeactivateRequest(), metadata=md),
        lambda md: device.Release(control_pb2.ReleaseRequest(), metadata=md),
        lambda md: device.PathClearPath(motion_pb2.PathClearPathRequest(path_name="long"),
                                        metadata=md),
    ]


async def main(target: str) -> None:
    stop = asyncio.Event()
    totals = {"reads": 0, "accepted": [], "refused": 0}
    subscribed = [asyncio.Event() for _ in range(SUBSCRIBERS)]
    seen = [{"tags": [], "lost": False} for _ in range(SUBSCRIBERS)]

    async def client(index: int) -> None:
        async with grpc.aio.insecure_channel(target) as channel:
            device = device_service_pb2_grpc.DeviceServiceStub(channel)
            tries, turn = attempts(device), index
            if index % 8 == 0:   # some with a session of their own, trying for the lock
                session = await AsyncSession(channel, f"crowd-{index}").open()
                tries.append(lambda md: session.lock())
            while not stop.is_set():
                await device.GetRobotPosition(settings_pb2.GetRobotPositionRequest())
                await device.GetDeviceState(control_pb2.GetDeviceStateRequest())
                totals["reads"] += 2
                turn += 1
                if turn % 5 == 0:
                    attempt = tries[(turn // 5) % len(tries)]
                    try:
                        await attempt(BOGUS if turn % 2 else ())
                        totals["accepted"].append(turn)
                    except grpc.aio.AioRpcError:
                        totals["refused"] += 1

    async def subscriber(index: int) -> None:
        async with grpc.aio.insecure_channel(target) as channel:
            stream = event_service_pb2_grpc.EventServiceStub(channel).Subscribe(
                event_service_pb2.SubscribeRequest())
            await stream.wait_for_connection()
            subscribed[index].set()
            async for reply in stream:
                event = reply.event
                if event.event_id == "events_lost":
                    seen[index]["lost"] = True
                elif event.event_id == "tag_reached":
                    seen[index]["tags"].append((event.command.command_id, event.command.tag_name))
                elif (event.event_id == "command_done"
                      and event.command.command == "PathMove"):
                    return

    tasks = [asyncio.create_task(client(i)) for i in range(CLIENTS)]
    readers = [asyncio.create_task(subscriber(i)) for i in range(SUBSCRIBERS)]
    for event in subscribed:
        await event.wait()
    while totals["reads"] < 2 * CLIENTS:
        await asyncio.sleep(0.05)
    print("ready", flush=True)
    await asyncio.get_running_loop().run_in_executor(None, sys.stdin.readline)
    stop.set()
    await asyncio.gather(*tasks)
    await asyncio.wait_for(asyncio.gather(*readers), 30)
    print(json.dumps({**totals, "subscribers": seen}), flush=True)


if __name__ == "__main__":
    asyncio.run(main(sys.argv[1]))
