"""What the bridges' tests share: a bridge's asyncio side on a thread of its own."""
from __future__ import annotations

import asyncio
import threading


class BridgeThread:
    """`make()` (a bridge with `run()` and `close()`) built and run on its own event loop."""

    def __init__(self, make):
        self._loop = asyncio.new_event_loop()
        built = threading.Event()

        def main():
            asyncio.set_event_loop(self._loop)
            self.bridge = make()
            built.set()
            self._loop.run_until_complete(self.bridge.run())

        self._thread = threading.Thread(target=main, name="bridge", daemon=True)
        self._thread.start()
        assert built.wait(30), "the bridge did not start"

    def call(self, func, *args):
        """`func(*args)` on the bridge's loop (a coroutine function or a plain one)."""
        async def run():
            result = func(*args)
            return await result if asyncio.iscoroutine(result) else result
        return asyncio.run_coroutine_threadsafe(run(), self._loop).result(30)

    def close(self) -> None:
        self._loop.call_soon_threadsafe(self.bridge.close)
        self._thread.join(30)
        assert not self._thread.is_alive(), "the bridge did not stop"
