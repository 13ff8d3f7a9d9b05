"""One device server as a program sees it: the client core every front end shares.

    link = DeviceLink(Endpoint("127.0.0.1:50051"), Identity("crcl-gateway"),
                      state=StreamStateRequest(rate_hz=100))
    await link.open()
    session = link.session("crcl-1", identity=link.identity.acting_for("crcl 10.0.0.7:5123"))

A link holds, for all the program's users of one device (a gateway's CRCL connections, a
supervisor's browsers, a script's one robot):
- `channel`: the program's channel on its own loop, for calls;
- `keeper`: the channel and threads where the session streams and their keep-alives run
  (keeper.py), so no computation on the program's loop can starve them;
- `events`: one event subscription, which follows every command by its id (event_feed.py);
- `state` (when asked for): one live state stream, its newest sample at hand (state_feed.py);
- `identity`: who calls (identity.py), on the link's own calls; each session may act for
  someone else.
`session()` makes an AsyncSession on the keeper; AsyncRobot (aio.py) adds the command set.
"""
from __future__ import annotations

import asyncio

import grpc

from landscape.client.aio_session import AsyncRsvpHandler, AsyncSession
from landscape.client.credentials import Endpoint, bearer
from landscape.client.errors import ServerUnavailable
from landscape.client.event_feed import EventFeed
from landscape.client.identity import Identity
from landscape.client.keeper import Keeper
from landscape.client.state_feed import StateFeed
from landscape.v1 import state_service_pb2


class DeviceLink:
    """`device`: an Endpoint (the link opens its channels and a keeper), or a grpc.aio channel
    of the caller's (then the session streams run on its loop, which must stay free, and the
    caller closes it). `token`: the role token the link's own calls (its feeds)
    present, when the endpoint has none because each session presents its person's
    (session(token=...)); with the endpoint's token, every call presents that one. `state`:
    the live state stream to keep (rate, frame, units), if any. `replay_events`: the event
    feed starts with the device's kept history (for a program that shows it)."""

    def __init__(self, device: Endpoint | grpc.aio.Channel, identity: Identity, *,
                 token: str | None = None,
                 state: state_service_pb2.StreamStateRequest | None = None,
                 replay_events: bool = False):
        self.endpoint = device if isinstance(device, Endpoint) else None
        self.target = self.endpoint.target if self.endpoint else "the channel given"
        self.identity = identity
        self.metadata = (*identity.metadata(), *bearer(token))   # on the link's own calls
        self.channel: grpc.aio.Channel | None = None if self.endpoint else device
        self.keeper: Keeper | None = None
        self.events: EventFeed | None = None
        self.state: StateFeed | None = None
        self._state_request = state
        self._replay = replay_events

    async def open(self, timeout: float | None = 10.0) -> "DeviceLink":
        """Channels, keeper and feeds; with a timeout, ServerUnavailable if the device does not
        answer within it (None: do not wait: the feeds keep trying)."""
        if self.endpoint is not None:
            self.channel = self.endpoint.aio_channel()
        if timeout is not None:
            try:
                async with asyncio.timeout(timeout):
                    await self.channel.channel_ready()
            except TimeoutError:
                await self._close_channel()
                raise ServerUnavailable(f"no device server at {self.target} answered within "
                                        f"{timeout} s", grpc.StatusCode.UNAVAILABLE) from None
        self.keeper = Keeper.start(self.endpoint) if self.endpoint is not None else None
        self.events = EventFeed(self.channel, self.metadata, self._replay)
        self.events.start()
        if self._state_request is not None:
            self.state = StateFeed(self.channel, self._state_request, self.metadata)
            self.state.start()
        return self

    def session(self, client_name: str, on_rsvp: AsyncRsvpHandler | None = None, *,
                identity: Identity | None = None, token: str | None = None) -> AsyncSession:
        """A session (not yet open) on this link's keeper (or the channel given), under
        `identity` (the link's by default), presenting `token` on its calls if given (a
        person's own). Its commands' waits end when it does (event_feed.py)."""
        session = AsyncSession(self.keeper or self.channel, client_name, on_rsvp,
                               identity=identity or self.identity, token=token)
        session.add_end_listener(lambda lost: self.events.wake())
        return session

    async def close(self) -> None:
        for feed in (self.state, self.events):
            if feed is not None:
                await feed.close()
        if self.keeper is not None:
            self.keeper.close()
        await self._close_channel()

    async def _close_channel(self) -> None:
        if self.endpoint is not None and self.channel is not None:
            await self.channel.close()
