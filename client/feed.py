"""What the link's two feeds (event_feed.py, state_feed.py) have alike: a task that keeps one
device stream open, the `listeners` every message goes to, and the `status_listeners` told
(code, details) each time the stream is registered (OK, "") or fails.
"""
from __future__ import annotations

import asyncio
from typing import Callable, Generic, TypeVar

import grpc

Message = TypeVar("Message")
StatusListener = Callable[[grpc.StatusCode, str], None]


class Feed(Generic[Message]):
    """A subclass's `_run()` keeps the stream open until cancelled; it hands each message to
    `_hand_on` and says how the stream stands with `_tell`."""

    def __init__(self, task_name: str):
        self.listeners: list[Callable[[Message], None]] = []
        self.status_listeners: list[StatusListener] = []
        self._task_name = task_name
        self._task: asyncio.Task | None = None

    def start(self) -> None:
        if self._task is None:
            self._task = asyncio.create_task(self._run(), name=self._task_name)

    async def close(self) -> None:
        if self._task is not None:
            self._task.cancel()
            await asyncio.gather(self._task, return_exceptions=True)

    async def _run(self) -> None:
        raise NotImplementedError

    def _hand_on(self, message: Message) -> None:
        for listener in self.listeners:
            listener(message)

    def _tell(self, code: grpc.StatusCode, details: str) -> None:
        for listener in self.status_listeners:
            listener(code, details)
