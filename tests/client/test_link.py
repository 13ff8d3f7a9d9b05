"""The client core as a program serving many people uses it (the gateway, a supervisor): one
DeviceLink, its event and state feeds shared by listeners, sessions acting for others."""
from __future__ import annotations

import asyncio

import grpc
import pytest

from landscape.client import AsyncRobot, DeviceLink, Endpoint, Frame, Identity
from landscape.client.aio_streams import state_request
from landscape.client.errors import CommandRefused, WrongState
from landscape.server.app import serve
from landscape.server.config import ServerConfig
from landscape.v1 import sensing_pb2
from support import start_server


def run(coroutine, timeout: float = 60):
    return asyncio.run(asyncio.wait_for(coroutine, timeout))


def test_the_feeds_reach_every_listener_and_the_history_is_replayed(server):
    async def body():
        async with AsyncRobot(server.target, "earlier") as robot, robot.control():
            pass                                        # events before the link is opened
        events, samples = [], []
        link = DeviceLink(Endpoint(server.target), Identity("watcher"), replay_events=True,
                          state=state_request(50, Frame.BASE, None, ()))
        await link.open()
        try:
            link.events.listeners.append(events.append)
            link.state.listeners.append(samples.append)
            await link.events.ready(10)
            async with AsyncRobot(link, "ann", identity=Identity("watcher", "ann")) as ann:
                async with ann.control():
                    move = await ann.move_relative([0.05, 0, 0, 0, 0, 0], Frame.JOINT)
                    await move.wait(timeout=30)
            while len(samples) < 3:
                await asyncio.sleep(0.05)
        finally:
            await link.close()
        return events, samples

    events, samples = run(body())
    sequences = [e.sequence for e in events]
    assert sequences[0] == 1 and sequences == sorted(set(sequences))   # all, in order
    assert any(e.command.phase == e.command.PHASE_DONE for e in events if e.HasField("command"))
    assert all(len(s.message.joint_positions) == 6 for s in samples)
    assert samples[-1].message.sequence > samples[0].message.sequence


def test_a_restarted_device_is_replayed_from_its_first_event_and_its_outage_said():
    """A supervisor shows a restarted device's history too: the event feed asked to replay
    starts again from the new device's first event; both feeds say when their stream failed
    and when it is back, and the state stream's terms are kept."""
    first = start_server()
    port = first.port
    servers = [first]          # those running
    events, told = [], []

    async def body():
        link = DeviceLink(Endpoint(first.target), Identity("watcher"), replay_events=True,
                          state=state_request(20, Frame.BASE, None, ()))
        await link.open()
        try:
            link.events.listeners.append(events.append)
            for name, feed in (("events", link.events), ("state", link.state)):
                feed.status_listeners.append(lambda code, why, name=name: told.append((name, code)))
            async with AsyncRobot(link, "before") as robot:
                await robot.lock()              # events 2 and on: the first run gets ahead
            await _until(lambda: len(events) >= 3)
            assert link.state.started.granted_rate_hz == pytest.approx(20, rel=0.1)
            await asyncio.to_thread(first.stop, None)
            servers.remove(first)
            await _until(lambda: ("events", grpc.StatusCode.UNAVAILABLE) in told
                         and ("state", grpc.StatusCode.UNAVAILABLE) in told)
            told.clear()
            events.clear()
            servers.append(await asyncio.to_thread(serve, ServerConfig(port=port,
                                                                       clock="lockstep")))
            await _until(lambda: events and ("state", grpc.StatusCode.OK) in told
                         and ("events", grpc.StatusCode.OK) in told)
        finally:
            await link.close()

    try:
        run(body())
    finally:
        for server in servers:
            server.stop(grace=None)
    assert events[0].sequence == 1 and events[0].state_change.to_state == "unlocked"


def test_a_robot_on_a_shared_link_reads_and_jogs_before_its_session_is_asked_for(server):
    """A supervisor's person: reads as themselves before any session; jog_stream relays the
    JogRequests a page makes (refused without the lock, in the client's words)."""
    async def body():
        link = DeviceLink(Endpoint(server.target), Identity("supervisor"))
        await link.open()
        try:
            ann = AsyncRobot(link, "ann", identity=Identity("supervisor", "ann"))
            assert not (await ann.get_device_state()).locked      # no session needed
            assert ann.session is None
            with pytest.raises(WrongState, match="open a session first"):
                await ann.lock()

            async def held():
                yield sensing_pb2.JogRequest(deadman=True, frame=Frame.JOINT,
                                             velocity=[5, 0, 0, 0, 0, 0])
            with pytest.raises(CommandRefused):
                async for _ in ann.jog_stream(held()):
                    pass
            await ann.open()                                     # now a session
            await ann.lock()
            assert (await ann.get_device_state()).lock_holder == "ann"
            await ann.close()
        finally:
            await link.close()

    run(body())


async def _until(condition, timeout: float = 30.0) -> None:
    async with asyncio.timeout(timeout):
        while not condition():
            await asyncio.sleep(0.05)
