"""What one browser has yet to receive: ordered frames in a bounded queue, and for each live
feed only its newest frame (latest wins), so a slow browser skips state samples instead of
queueing them, and never slows the device links or another browser."""
from __future__ import annotations

import asyncio
from collections import deque


class TooSlow(Exception):
    """The browser fell behind by more ordered frames than the outbox keeps."""


class Outbox:
    def __init__(self, max_ordered: int = 2000):
        self._ordered: deque[str] = deque()
        self._latest: dict[tuple[str, str], str] = {}   # (device, feed) -> newest frame
        self._max_ordered = max_ordered
        self._ready = asyncio.Event()
        self.overflowed = False
        self.closed = False

    def put(self, text: str) -> None:
        """An ordered frame (event, reply, status): each one is delivered, in order."""
        if len(self._ordered) >= self._max_ordered:
            self.overflowed = True
        else:
            self._ordered.append(text)
        self._ready.set()

    def put_latest(self, key: tuple[str, str], text: str) -> None:
        """A frame of a live feed: replaces the feed's frame not sent yet."""
        self._latest[key] = text
        self._ready.set()

    def close(self) -> None:
        self.closed = True
        self._ready.set()

    async def take(self) -> list[str]:
        """Everything pending, ordered frames first; waits until something is. An empty list
        means the outbox was closed; TooSlow when it overflowed."""
        while True:
            if self.overflowed:
                raise TooSlow(f"more than {self._max_ordered} frames behind")
            if self.closed:
                return []
            if self._ordered or self._latest:
                batch = [*self._ordered, *self._latest.values()]
                self._ordered.clear()
                self._latest.clear()
                return batch
            self._ready.clear()
            await self._ready.wait()
