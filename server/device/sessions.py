"""Client sessions: alive while their stream is open and their keep-alives arrive (DESIGN.md 5).

A session ends once, for one reason (stream closed, keep-alive timeout, server stopping); the
registry then calls `on_end(session, reason)`, which the device uses for the seed's disconnect
handler (section 2.2). Keep-alive timeouts are checked by one watchdog thread. What the device
sends a session (RSVP questions) waits in its bounded `outbox` until the session's stream,
on the event loop, takes it.
"""
from __future__ import annotations

import asyncio
import itertools
import logging
import secrets
import threading
import time
from typing import Any, Callable

log = logging.getLogger(__name__)

OUTBOX_SIZE = 64      # RSVP questions one session may have waiting to be sent


class Outbox:
    """Items for a session's stream, put from any thread, taken on the stream's event loop.
    Bounded: `put` returns False (and keeps nothing) once `maxsize` items wait."""

    END = object()     # taken last: the session ended

    def __init__(self, loop: asyncio.AbstractEventLoop | None, maxsize: int = OUTBOX_SIZE):
        self._loop = loop
        self._queue: asyncio.Queue = asyncio.Queue(maxsize + 1)   # room for END
        self._count = 0
        self._maxsize = maxsize
        self._lock = threading.Lock()

    def put(self, item: Any) -> bool:
        with self._lock:
            if self._count >= self._maxsize:
                return False
            self._count += 1
        self._deliver(item)
        return True

    def end(self) -> None:
        self._deliver(Outbox.END)

    async def get(self) -> Any:
        item = await self._queue.get()
        if item is not Outbox.END:
            with self._lock:
                self._count -= 1
        return item

    def _deliver(self, item: Any) -> None:
        if self._loop is None:
            return    # no stream to send to (tests opening sessions directly)
        try:
            self._loop.call_soon_threadsafe(self._queue.put_nowait, item)
        except RuntimeError:
            pass      # the loop is closed: the stream is gone


class Session:
    def __init__(self, session_id: str, client_name: str,
                 loop: asyncio.AbstractEventLoop | None = None):
        self.id = session_id
        self.secret = secrets.token_urlsafe(24)   # given only on the session stream
        self.client_name = client_name
        self.last_seen = time.monotonic()
        self.outbox = Outbox(loop)    # what the Connect stream sends to the client
        self.ended = threading.Event()
        self.end_reason = ""
        self.end_code = ""            # the gRPC status the server ends the stream with, if any

    def __repr__(self) -> str:
        return f"Session({self.id!r}, {self.client_name!r})"


class SessionRegistry:
    def __init__(self, on_end: Callable[[Session, str], None],
                 keepalive_interval: float = 0.5, keepalive_timeout: float = 2.0):
        self.keepalive_interval = keepalive_interval
        self.keepalive_timeout = keepalive_timeout
        self._on_end = on_end
        self._sessions: dict[str, Session] = {}
        self._lock = threading.Lock()
        self._numbers = itertools.count(1)
        self._stopping = threading.Event()
        self._watchdog = threading.Thread(target=self._watch, name="session-watchdog", daemon=True)
        self._watchdog.start()

    def open(self, client_name: str, loop: asyncio.AbstractEventLoop | None = None) -> Session:
        session = Session(f"s{next(self._numbers)}-{secrets.token_hex(4)}",
                          client_name or "anonymous", loop)
        with self._lock:
            self._sessions[session.id] = session
        log.info("session %s opened by '%s'", session.id, session.client_name)
        return session

    def count(self) -> int:
        """Sessions open now."""
        return len(self._sessions)

    def get(self, session_id: str) -> Session | None:
        with self._lock:
            return self._sessions.get(session_id)

    def owned(self, session_id: str, secret: str) -> Session | None:
        """The open session `session_id` if `secret` is its own, else None."""
        session = self.get(session_id)
        if session is None or not secrets.compare_digest(secret.encode(), session.secret.encode()):
            return None
        return session

    def touch(self, session: Session) -> None:
        session.last_seen = time.monotonic()

    def end(self, session: Session, reason: str, code: str = "") -> None:
        """End `session` (once; later calls do nothing). `code` names the gRPC status its
        stream closes with when the server ends it ("" when the stream is gone already)."""
        with self._lock:
            if self._sessions.pop(session.id, None) is None:
                return  # already ended
        session.end_reason, session.end_code = reason, code
        session.ended.set()
        session.outbox.end()
        log.info("session %s (%s) ended: %s", session.id, session.client_name, reason)
        try:
            self._on_end(session, reason)
        except Exception:
            log.exception("disconnect handler failed for %s", session.id)

    def close(self) -> None:
        self._stopping.set()
        with self._lock:
            sessions = list(self._sessions.values())
        for session in sessions:
            self.end(session, "the server is stopping", "UNAVAILABLE")

    def _watch(self) -> None:
        period = min(0.1, self.keepalive_timeout / 4)
        while not self._stopping.wait(period):
            deadline = time.monotonic() - self.keepalive_timeout
            with self._lock:
                stale = [s for s in self._sessions.values() if s.last_seen < deadline]
            for session in stale:
                self.end(session, f"no keep-alive for {self.keepalive_timeout:g} s",
                         "DEADLINE_EXCEEDED")
