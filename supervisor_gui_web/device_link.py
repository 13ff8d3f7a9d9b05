"""One device server as the dashboard sees it: a grpc.aio channel, the feeds every browser
shares (live state, events, the read-only status, the cell around the arm), and the browsers
watching it.

One StreamState and one Subscribe per device serve every browser: the device server thins the
state to the display rate once, and each browser's outbox keeps only the newest sample.

One channel per device carries everyone's calls; who a call is for rides on the call
(caller.py). The feeds go as the supervisor itself, with its own (viewer) token when the
devices use tokens; a person's calls go through `caller(...)` with theirs.
"""
from __future__ import annotations

import asyncio
import logging
from collections import deque

from landscape.client.credentials import ClientTLS, open_aio_channel
from landscape.supervisor import wire
from landscape.supervisor.caller import CallerChannel, identity_metadata
from landscape.supervisor.config import DeviceTarget
from landscape.supervisor.feeds import EventFeed, StatusPoll
from landscape.supervisor.outbox import Outbox
from landscape.supervisor.state_feed import StateFeed
from landscape.supervisor.world_feed import WorldFeed

log = logging.getLogger(__name__)

FEEDS_FOR = "every browser"   # landscape-on-behalf-of of the shared feeds


class DeviceLink:
    def __init__(self, target: DeviceTarget, display_rate_hz: float, tls: ClientTLS | None = None,
                 token: str | None = None, history: int = 500):
        self.name = target.name
        self.target = target.address
        self._channel = open_aio_channel(target.address, tls)
        # What the feeds call through: as the supervisor, for every browser.
        self.channel = CallerChannel(self._channel, identity_metadata(FEEDS_FOR, token))
        self._watchers: set[Outbox] = set()
        self._history: deque[str] = deque(maxlen=history)   # the newest event frames, for joiners
        self._latest: dict[str, str] = {}                   # feed -> its newest frame, for joiners
        self.status_poll = StatusPoll(self)
        self.world = WorldFeed(self)
        self.feeds = [StateFeed(self, display_rate_hz, on_end_effector=self.world.kick),
                      EventFeed(self, on_state_change=self._state_changed), self.status_poll,
                      self.world]
        self._tasks: list[asyncio.Task] = []

    def start(self) -> None:
        self._tasks = [asyncio.create_task(feed.run(), name=f"{self.name}-{type(feed).__name__}")
                       for feed in self.feeds]

    async def close(self) -> None:
        for task in self._tasks:
            task.cancel()
        await asyncio.gather(*self._tasks, return_exceptions=True)
        await self._channel.close()

    def caller(self, metadata: tuple[tuple[str, str], ...]) -> CallerChannel:
        """The device's channel for calls with `metadata` (caller.identity_metadata)."""
        return CallerChannel(self._channel, metadata)

    def _state_changed(self) -> None:
        self.status_poll.kick()
        self.world.kick()   # a tool change's steps, a motion's start and end

    # ---- browsers
    def join(self, outbox: Outbox) -> None:
        """A browser starts watching: it gets the kept events, then the newest of each feed."""
        for text in self._history:
            outbox.put(text)
        for text in self._latest.values():
            outbox.put(text)
        self._watchers.add(outbox)

    def leave(self, outbox: Outbox) -> None:
        self._watchers.discard(outbox)

    # ---- what the feeds publish
    def publish_event(self, rpc: str, reply=None, status=None) -> None:
        """An ordered frame every browser receives and a joiner is replayed."""
        text = wire.frame(self.name, rpc, reply=reply, status=status)
        self._history.append(text)
        for outbox in self._watchers:
            outbox.put(text)

    def publish_latest(self, feed: str, rpc: str, reply=None, status=None,
                       ordered: bool = False) -> None:
        """The newest frame of a feed (state sample, a status read): a browser that is behind
        gets only the newest one. `ordered` frames (a stream's start, a failure) are delivered
        every one, in order."""
        text = wire.frame(self.name, rpc, reply=reply, status=status)
        self._latest[feed] = text
        for outbox in self._watchers:
            if ordered:
                outbox.put(text)
            else:
                outbox.put_latest((self.name, feed), text)

    def forget_latest(self, feed: str) -> None:
        self._latest.pop(feed, None)
