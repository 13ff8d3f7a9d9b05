"""The thread that carries out the device's safety actions (DESIGN.md section 5).

The disconnect handler and the shutdown stop can take a second of braking and powering down.
They never run on a gRPC thread or the event loop, where they would hold up other clients'
calls and keep-alives, nor behind a command: they are handed to this one thread, which runs
them in the order they came. A stop itself reaches the controller at once (it is a message to
the cycle, sent without waiting for anything); only the waiting for the arm to come to rest
happens here.
"""
from __future__ import annotations

import logging
import queue
import threading
from typing import Callable

log = logging.getLogger(__name__)


class SafetyWorker:
    def __init__(self, name: str = "safety"):
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._idle = threading.Event()
        self._idle.set()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, action: Callable[[], None], what: str) -> None:
        self._idle.clear()
        self._jobs.put((action, what))

    def wait_idle(self, timeout: float) -> bool:
        """True once every action submitted so far has run (for shutdown and tests)."""
        return self._idle.wait(timeout)

    def close(self, timeout: float = 5.0) -> None:
        self._jobs.put(None)
        self._thread.join(timeout)

    def _run(self) -> None:
        while (job := self._jobs.get()) is not None:
            action, what = job
            try:
                action()
            except Exception:
                log.exception("safety action failed: %s", what)
            if self._jobs.empty():
                self._idle.set()
        self._idle.set()
