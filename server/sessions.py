"""Client sessions: alive while their stream is open and their keep-alives arrive (DESIGN.md 5).

A session ends once, for one reason (stream closed, keep-alive timeout, server stopping); the
registry then calls `on_end(session, reason)`, which the device uses for the seed's disconnect
handler (section 2.2). Keep-alive timeouts are checked by one watchdog thread.
"""
from __future__ import annotations

import itertools
import logging
import queue
import secrets
import threading
import time
from typing import Callable

log = logging.getLogger(__name__)


class Session:
    def __init__(self, session_id: str, client_name: str):
        self.id = session_id
        self.secret = secrets.token_urlsafe(24)   # given only on the session stream
        self.client_name = client_name
        self.last_seen = time.monotonic()
        self.outbox: queue.Queue = queue.Queue()   # what the Connect stream sends to the client
        self.ended = threading.Event()
        self.end_reason = ""

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

    def open(self, client_name: str) -> Session:
        session = Session(f"s{next(self._numbers)}-{secrets.token_hex(4)}", client_name or "anonymous")
        with self._lock:
            self._sessions[session.id] = session
        log.info("session %s opened by %r", session.id, session.client_name)
        return session

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

    def end(self, session: Session, reason: str) -> None:
        with self._lock:
            if self._sessions.pop(session.id, None) is None:
                return  # already ended
        session.end_reason = reason
        session.ended.set()
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
            self.end(session, "server stopping")

    def _watch(self) -> None:
        period = min(0.1, self.keepalive_timeout / 4)
        while not self._stopping.wait(period):
            deadline = time.monotonic() - self.keepalive_timeout
            with self._lock:
                stale = [s for s in self._sessions.values() if s.last_seen < deadline]
            for session in stale:
                self.end(session, f"no keep-alive for {self.keepalive_timeout:g} s")
