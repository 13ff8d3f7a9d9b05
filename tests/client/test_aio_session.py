"""The asyncio session against a real device server: lock, lease on calls, disconnect."""
from __future__ import annotations

import asyncio

import grpc

from landscape.client import AsyncSession
from landscape.server.device.states import State
from landscape.v1 import control_pb2, device_service_pb2_grpc

from support import wait_until


def test_async_session_locks_commands_and_its_end_releases(server):
    async def body():
        async with grpc.aio.insecure_channel(server.target) as channel:
            session = await AsyncSession(channel, "async-supervisor").open()
            await session.lock()
            device = device_service_pb2_grpc.DeviceServiceStub(channel)
            reply = await device.Activate(control_pb2.ActivateRequest(),
                                          metadata=session.metadata(), timeout=10)
            assert reply.ret_val.ret_msg == "drives on"
            state = await device.GetDeviceState(control_pb2.GetDeviceStateRequest(), timeout=5)
            assert state.lock_holder == "async-supervisor"
            await session.close()

    asyncio.run(asyncio.wait_for(body(), 30))
    wait_until(lambda: server.device.state is State.UNLOCKED, timeout=10)


def test_async_session_hears_and_answers_the_devices_questions(server):
    """The session stream's reader hears RSVP questions (it once died on its first read)."""
    async def body():
        async with grpc.aio.insecure_channel(server.target) as channel:
            session = await AsyncSession(channel, "answering",
                                         on_rsvp=lambda request: ("reset", [])).open()
            await session.lock()
            server.link.between_cycles(lambda c: c.panel.press_estop())
            await asyncio.sleep(0.2)
            server.link.between_cycles(lambda c: c.panel.release_estop())
            question = await asyncio.wait_for(session.rsvp_requests.get(), 10)
            assert question.event_id == "estop_released" and not session.ended.is_set()
            for _ in range(200):   # the answer "reset" takes the device back to Inactive
                if server.device.state is State.INACTIVE:
                    break
                await asyncio.sleep(0.05)
            assert server.device.state is State.INACTIVE
            await session.close()

    asyncio.run(asyncio.wait_for(body(), 30))
