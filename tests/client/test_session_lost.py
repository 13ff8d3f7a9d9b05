"""Lost sessions and locks are never silent (issue 25 item 4), against a real device server:
a busy event loop does not starve the session's keep-alives; a session the device ends
fails the command waited for with the device's reason, and every later call that needs the
lock, and nothing takes the lock back."""
from __future__ import annotations

import asyncio
import time

import grpc
import pytest

from landscape.client import AsyncRobot, Frame, Robot, SessionEnded
from landscape.server.device.states import State

from support import start_server, wait_until

FAR = [2.5, 0, 1.57, 0, 1.57, 0]      # at 2 % speed, many seconds away


@pytest.fixture
def paced():
    """Motions last as long as on the arm (lock-step at real-time pace)."""
    running = start_server(lockstep_pace=1.0)
    yield running
    running.stop(grace=None)


def end_session(server, session_id: str, reason: str = "no keep-alive for 2 s") -> None:
    """The device ends the session as its keep-alive watchdog does."""
    registry = server.device.sessions
    registry.end(registry.get(session_id), reason, "DEADLINE_EXCEEDED")


def test_a_blocked_event_loop_keeps_its_session_and_lock(server):
    """The program's loop does nothing for 3 s (more than the device's 2 s keep-alive
    timeout): the keep-alives go out from the keeper's threads all the same."""
    async def body():
        async with AsyncRobot(server.target, "busy") as robot:
            await robot.lock()
            time.sleep(3.0)                  # a computation that never yields
            await robot.activate()
            state = await robot.get_device_state()
            assert state.locked and state.lock_holder == "busy"
            await robot.relinquish()

    asyncio.run(asyncio.wait_for(body(), 60))


def test_a_session_the_device_ends_fails_the_move_with_the_devices_reason(paced):
    async def body():
        async with AsyncRobot(paced.target, "starved") as robot:
            await robot.lock()
            await robot.activate()
            move = await robot.move_absolute(FAR, Frame.JOINT, speed=2)
            while paced.device.state is not State.MOVING:
                await asyncio.sleep(0.01)
            end_session(paced, robot.session.session_id)
            with pytest.raises(SessionEnded) as lost:
                await move.wait(timeout=60)
            assert lost.value.reason == "no keep-alive for 2 s" and lost.value.held_lock
            assert lost.value.code is grpc.StatusCode.DEADLINE_EXCEEDED
            assert str(lost.value).startswith("your session ended: no keep-alive for 2 s")
            with pytest.raises(SessionEnded):          # the lock is gone, and says why
                await robot.activate()
            with pytest.raises(SessionEnded):          # and is not taken back
                await robot.lock()
            assert await robot.relinquish() is not None   # nothing to hand back
            state = await robot.get_device_state()     # reads go on
            assert not state.locked

    asyncio.run(asyncio.wait_for(body(), 90))
    wait_until(lambda: paced.device.state is State.UNLOCKED, timeout=10)


def test_the_blocking_robot_hears_the_loss_while_it_waits(paced):
    heard = []
    with Robot(paced.target, "blocking") as robot:
        robot.when_lost(heard.append)
        robot.lock()
        robot.activate()
        move = robot.move_absolute(FAR, Frame.JOINT, speed=2)
        wait_until(lambda: paced.device.state is State.MOVING, timeout=10)
        end_session(paced, robot.session.session_id, "the server is stopping")
        with pytest.raises(SessionEnded, match="your session ended: the server is stopping"):
            move.wait(timeout=60)
        wait_until(lambda: heard, timeout=5)
        assert heard[0] is robot.lost
        with pytest.raises(SessionEnded):
            robot.set_speed(50)
    wait_until(lambda: not paced.device.status().locked, timeout=10)
