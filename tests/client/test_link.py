"""The client core as a program serving many people uses it (the gateway, a supervisor): one
DeviceLink, its event and state feeds shared by listeners, sessions acting for others."""
from __future__ import annotations

import asyncio

from landscape.client import AsyncRobot, DeviceLink, Endpoint, Frame, Identity
from landscape.client.aio_streams import state_request


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
