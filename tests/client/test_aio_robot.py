"""The asyncio client against a real device server: control(), waiting, refusals."""
from __future__ import annotations

import asyncio

import pytest

from landscape.client import AsyncRobot, CommandTimeout, DeviceState, Frame, WrongState
from landscape.server.device.states import State
from landscape.v1 import sensing_pb2

from support import start_server

AWAY = [0.8, -0.3, 1.2, 0.4, 1.2, 0.5]


def run(coroutine, timeout: float = 60):
    return asyncio.run(asyncio.wait_for(coroutine, timeout))


def test_async_control_moves_waits_and_hands_back_when_the_body_raises():
    server = start_server(lockstep_pace=1.0)

    async def body():
        async with AsyncRobot(server.target, "async-mover") as robot:
            async with robot.control():
                move = await robot.move_relative([0.05, 0, 0, 0, 0, 0], Frame.JOINT)
                done = await move.wait(timeout=30)
                assert done.command.command_id == move.command_id
            with pytest.raises(RuntimeError):
                async with robot.control():
                    await robot.move_absolute(AWAY, Frame.JOINT)
                    while server.device.state is not State.MOVING:
                        await asyncio.sleep(0.01)
                    raise RuntimeError("the body failed")
            state = await robot.get_device_state()
            assert DeviceState(state.state) is DeviceState.UNLOCKED and not state.locked
            with pytest.raises(WrongState):
                await robot.activate()   # not locked any more

    try:
        run(body())
    finally:
        server.stop(grace=None)


def test_async_events_and_follow(server):
    async def body():
        async with AsyncRobot(server.target, "async-follower") as robot:
            async with robot.control():
                move = await robot.move_absolute(AWAY, Frame.JOINT, point_name="away")
                phases = [e.event_id async for e in move.follow(timeout=30)]
            assert phases == ["command_started", "command_done"]
            ids = []
            async for event in robot.events(after_sequence=0, timeout=10):
                ids.append(event.event_id)
                if event.event_id == "command_done":
                    break
            assert "command_started" in ids

    run(body())


def test_async_wait_shorter_than_the_move_raises_command_timeout():
    server = start_server(lockstep_pace=1.0)

    async def body():
        async with AsyncRobot(server.target, "async-impatient") as robot:
            async with robot.control():
                move = await robot.move_absolute(AWAY, Frame.JOINT)
                with pytest.raises(CommandTimeout, match=move.command_id):
                    await move.wait(timeout=0.05)
                assert server.device.state is State.MOVING
                assert (await move.wait(timeout=60)).event_id == "command_done"

    try:
        run(body())
    finally:
        server.stop(grace=None)


def test_async_jog_moves_the_joint_while_the_deadman_is_held():
    server = start_server(lockstep_pace=1.0)

    async def held(count: int):
        for _ in range(count):
            yield [30, 0, 0, 0, 0, 0]
            await asyncio.sleep(0.02)   # a pendant's pace: well inside the deadman timeout

    async def body():
        async with AsyncRobot(server.target, "async-jogger") as robot:
            async with robot.control():
                await robot.manual_control(sensing_pb2.MANUAL_CONTROL_TYPE_TEACHPENDANT)
                before = (await robot.get_robot_position()).joint_position[0]
                replies = [reply async for reply in robot.jog(held(25), Frame.JOINT)]
                after = (await robot.get_robot_position()).joint_position[0]
        return before, after, replies

    try:
        before, after, replies = run(body())
    finally:
        server.stop(grace=None)
    assert after > before + 0.01
    assert replies and len(replies[-1].joint_position) == 6
