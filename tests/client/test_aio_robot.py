"""The asyncio client against a real device server: control(), waiting, refusals."""
from __future__ import annotations

import asyncio

import pytest

from landscape.client import AsyncRobot, DeviceState, Frame, WrongState
from landscape.server.states import State

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
