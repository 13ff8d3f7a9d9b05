"""Where session streams live: an event loop and a channel of their own, on a thread of their own.

A session's keep-alives must reach the device every interval it asks for (it ends the session,
stopping the arm and freeing the lock, after a few missed ones), whatever the program does
meanwhile: a long computation on its event loop, a blocking call, a slow callback. So the
session streams do not run on the caller's loop. A `Keeper` runs a small event loop on a
daemon thread with its own grpc.aio channel to the device, and does nothing else there; one
Keeper serves every session a program opens on that device (the gateway's CRCL connections,
the supervisor's browsers). Callers hand it coroutines (`run`, `submit`: thread-safe) and it
calls them back on their own loops.

`Keeper.on(channel)` keeps the streams on the loop of a channel the caller opened itself (from
a channel no second one can be made): the caller's loop must then stay free.
"""
from __future__ import annotations

import asyncio
import concurrent.futures
import threading
from typing import Any, Coroutine

import grpc

CLOSE_TIMEOUT = 5.0     # s for the keeper's channel to close and its thread to end


class Keeper:
    def __init__(self, loop: asyncio.AbstractEventLoop, channel: grpc.aio.Channel,
                 thread: threading.Thread | None = None):
        self.loop = loop            # where the session streams run
        self.channel = channel      # bound to that loop
        self._thread = thread       # ours to stop, or None when the loop is the caller's

    @classmethod
    def start(cls, endpoint, name: str = "landscape-keeper") -> "Keeper":
        """A thread with its own loop and a channel from `endpoint` (credentials.Endpoint)."""
        loop = asyncio.new_event_loop()
        thread = threading.Thread(target=loop.run_forever, daemon=True, name=name)
        thread.start()

        async def open_channel() -> grpc.aio.Channel:   # a grpc.aio channel binds to its loop
            return endpoint.aio_channel()
        channel = asyncio.run_coroutine_threadsafe(open_channel(), loop).result(CLOSE_TIMEOUT)
        return cls(loop, channel, thread)

    @classmethod
    def on(cls, channel: grpc.aio.Channel) -> "Keeper":
        """The caller's own loop and channel (call from a coroutine on that loop)."""
        return cls(asyncio.get_running_loop(), channel)

    def submit(self, coroutine: Coroutine) -> concurrent.futures.Future:
        """Run `coroutine` on the keeper's loop (from any thread)."""
        return asyncio.run_coroutine_threadsafe(coroutine, self.loop)

    async def run(self, coroutine: Coroutine) -> Any:
        """Await `coroutine` run on the keeper's loop, from a coroutine on any loop."""
        return await asyncio.wrap_future(self.submit(coroutine))

    def call_soon(self, callback, *args) -> None:
        """Call `callback(*args)` on the keeper's loop (from any thread)."""
        self.loop.call_soon_threadsafe(callback, *args)

    async def _wind_up(self) -> None:
        """The streams still open end (their sessions with them), then the channel."""
        tasks = [t for t in asyncio.all_tasks() if t is not asyncio.current_task()]
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)
        await self.channel.close()

    def close(self) -> None:
        """Close the channel and end the thread (a Keeper on the caller's loop owns nothing)."""
        if self._thread is None or not self._thread.is_alive():
            return
        try:
            self.submit(self._wind_up()).result(CLOSE_TIMEOUT)
        except (concurrent.futures.TimeoutError, RuntimeError):
            pass
        self.loop.call_soon_threadsafe(self.loop.stop)
        self._thread.join(CLOSE_TIMEOUT)
        if not self._thread.is_alive():
            self.loop.close()
