"""Robot, AsyncRobot and AsyncRobot on a given channel, against a device server with TLS and
role tokens (issue 16): the credentials are theirs to open the channel with."""
from __future__ import annotations

import asyncio

import pytest

from landscape.client import (AsyncRobot, ClientTLS, DeviceLink, Endpoint, Frame, Identity,
                              NotAllowed, Robot, open_aio_channel)
from landscape.client.errors import TransportError
from landscape.server.device.states import State

from support import make_keys

GOAL = [0.4, -0.1, 1.5, 0.0, 1.4, 0.2]


def test_robot_over_tls_with_an_operator_token_moves(secured, keys):
    with Robot(secured.target, "tls-operator", tls=keys.tls(),
               token=keys.token("operator")) as robot, robot.control():
        robot.move_absolute(GOAL, Frame.JOINT).wait(timeout=60)
        assert robot.get_robot_position().joint_position == pytest.approx(GOAL, abs=1e-5)
    assert secured.device.state is State.UNLOCKED


def test_robot_with_a_viewer_token_reads_but_may_not_lock(secured, keys):
    with Robot(secured.target, "tls-viewer", tls=keys.tls(), token=keys.token("viewer")) as robot:
        assert robot.get_device_state().state
        with pytest.raises(NotAllowed) as refused:
            robot.lock()
    assert refused.value.reason == "ROLE_TOO_LOW"
    assert secured.device.state is State.UNLOCKED


def test_robot_without_trusting_the_ca_cannot_connect(secured, keys, tmp_path):
    stranger = make_keys(tmp_path / "stranger")
    with pytest.raises(TransportError):
        Robot(secured.target, "untrusting", tls=stranger.tls(),
              token=keys.token("operator")).open(timeout=2)


def test_a_channel_and_credentials_together_are_refused(keys):
    with pytest.raises(ValueError, match="belong to the channel"):
        Robot(object(), "confused", tls=keys.tls())
    with pytest.raises(ValueError, match="belong to the channel"):
        AsyncRobot(object(), "confused", token="t")


def test_async_robot_over_tls_with_a_token_and_on_a_given_channel(secured, keys):
    async def body():
        async with AsyncRobot(secured.target, "aio-tls", tls=keys.tls(),
                              token=keys.token("operator")) as robot:
            async with robot.control():
                move = await robot.move_absolute(GOAL, Frame.JOINT)
                await move.wait(timeout=60)
        async with open_aio_channel(secured.target, ClientTLS(ca=str(keys.certs.ca)),
                                    keys.token("viewer")) as channel:
            async with AsyncRobot(channel, "aio-viewer") as robot:
                position = await robot.get_robot_position()
                with pytest.raises(NotAllowed):
                    await robot.lock()
            assert channel.get_state() is not None   # still the caller's to close
        return position

    position = asyncio.run(asyncio.wait_for(body(), 120))
    assert list(position.joint_position) == pytest.approx(GOAL, abs=1e-5)


def test_one_link_serves_each_person_with_their_own_token(secured, keys):
    """As a supervisor does: one channel without a token, the shared feeds under the
    program's viewer token, and each person's robot presenting that person's token."""
    async def body():
        link = await DeviceLink(Endpoint(secured.target, keys.tls()), Identity("supervisor"),
                                token=keys.token("viewer")).open()
        try:
            await link.events.ready(10)                 # the feed is let in as a viewer
            operator = AsyncRobot(link, "ann", token=keys.token("operator"),
                                  identity=Identity("supervisor", "ann"))
            async with operator:
                async with operator.control():
                    move = await operator.move_absolute(GOAL, Frame.JOINT)
                    await move.wait(timeout=60)
            viewer = AsyncRobot(link, "bob", token=keys.token("viewer"),
                                identity=Identity("supervisor", "bob"))
            async with viewer:
                with pytest.raises(NotAllowed):
                    await viewer.lock()
                return await viewer.get_robot_position()
        finally:
            await link.close()

    position = asyncio.run(asyncio.wait_for(body(), 120))
    assert list(position.joint_position) == pytest.approx(GOAL, abs=1e-5)
