"""An event loop on a thread of its own, so that blocking programs use the asyncio client core.

`Robot` (robot.py) runs an AsyncRobot here: each blocking method submits a coroutine and
waits for its result; an interrupted wait (Ctrl-C) cancels the coroutine. `iterate` turns an
async iterator into a blocking one, `pump` a blocking iterable (paced by the caller's sleeps)
into an async one that never holds up the loop.
"""
from __future__ import annotations

import asyncio
import threading
from typing import AsyncIterable, AsyncIterator, Coroutine, Iterable, Iterator, TypeVar

T = TypeVar("T")
STOP_TIMEOUT = 5.0      # s for the thread to end once its loop is stopped
_DONE = object()


class LoopThread:
    def __init__(self, name: str = "landscape-loop"):
        self.loop = asyncio.new_event_loop()
        self._thread = threading.Thread(target=self.loop.run_forever, daemon=True, name=name)
        self._thread.start()

    def run(self, coroutine: Coroutine[object, object, T], timeout: float | None = None) -> T:
        """The coroutine's result (or exception), run on the loop; cancelled if the wait is
        interrupted."""
        future = asyncio.run_coroutine_threadsafe(coroutine, self.loop)
        try:
            return future.result(timeout)
        except BaseException:
            future.cancel()
            raise

    def iterate(self, iterable: AsyncIterable[T]) -> Iterator[T]:
        """Each item of an async iterable, waited for here."""
        iterator = iterable.__aiter__()

        async def step():
            return await anext(iterator, _DONE)
        try:
            while (item := self.run(step())) is not _DONE:
                yield item
        finally:
            if hasattr(iterator, "aclose") and self._thread.is_alive():
                self.run(iterator.aclose())

    def stop(self) -> None:
        if self._thread.is_alive():
            self.loop.call_soon_threadsafe(self.loop.stop)
            self._thread.join(STOP_TIMEOUT)
        if not self._thread.is_alive() and not self.loop.is_closed():
            self.loop.close()


async def pump(iterable: Iterable[T]) -> AsyncIterator[T]:
    """The items of a blocking iterable, read on a thread of their own as they come."""
    loop = asyncio.get_running_loop()
    queue: asyncio.Queue = asyncio.Queue()

    def read() -> None:
        try:
            for item in iterable:
                loop.call_soon_threadsafe(queue.put_nowait, (item, None))
            loop.call_soon_threadsafe(queue.put_nowait, (_DONE, None))
        except BaseException as error:   # the caller's iterable failed: raise it there
            loop.call_soon_threadsafe(queue.put_nowait, (_DONE, error))

    threading.Thread(target=read, daemon=True, name="landscape-pump").start()
    while True:
        item, error = await queue.get()
        if error is not None:
            raise error
        if item is _DONE:
            return
        yield item
