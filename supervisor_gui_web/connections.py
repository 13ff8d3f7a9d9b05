"""The connections the backend holds before anyone showed a sign-in: bounded in time and in
number, so that half-sent requests cannot pile up.

- Time: a request's head (request line and headers) must be complete within
  HEADER_TIMEOUT_S of the connection's start (or of the previous response on a kept-alive
  connection), or the connection is closed. This is aiohttp's keep-alive timer
  (`keepalive_timeout`): in the aiohttp we pin (3.14.5, aio-libs/aiohttp#13681) it starts
  when a connection is made, and when it fires with no complete request head received it
  closes the connection (test_http_guard.py checks that it still does). The same figure
  closes a kept-alive connection idle that long. A request body (only the sign-in has one) is read
  under the same bound (sign_in_routes.py).
- Number: at most `limit` connections that have not yet carried a valid sign-in are held at
  once; one more is closed as soon as it is accepted. A connection that carries a valid
  sign-in (the middleware vouches for it) no longer counts, so the pages of signed-in people
  are never pushed out by strangers.
"""
from __future__ import annotations

import asyncio
import logging
import time

from aiohttp import web

log = logging.getLogger(__name__)

HEADER_TIMEOUT_S = 5.0         # s for a request's head to arrive (documented in docs/supervisor.md)
MAX_UNAUTHENTICATED = 64       # connections held that never showed a sign-in
REFUSAL_LOG_PERIOD_S = 60.0


class _Refused(asyncio.Protocol):
    """A connection over the limit: closed at once, nothing read."""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        transport.abort()


class ConnectionGuard:
    """The protocol factory in front of aiohttp's `web.Server`: serve(server) once the
    runner is set up, then pass the guard to loop.create_server."""

    def __init__(self, limit: int = MAX_UNAUTHENTICATED):
        if limit < 1:
            raise ValueError("the limit of unauthenticated connections is at least 1")
        self.limit = limit
        self._server: web.Server | None = None
        self._vouched: set = set()
        self._refused = 0
        self._refusal_logged = 0.0

    def serve(self, server: web.Server) -> "ConnectionGuard":
        self._server = server
        return self

    def vouch(self, connection) -> None:
        """`connection` (a request's `protocol`) carried a valid sign-in."""
        self._vouched.add(connection)

    def unauthenticated(self) -> int:
        connections = set(self._server.connections)
        self._vouched &= connections
        return len(connections) - len(self._vouched)

    def __call__(self) -> asyncio.Protocol:
        if self.unauthenticated() >= self.limit:
            self._refused += 1
            now = time.monotonic()
            if now - self._refusal_logged >= REFUSAL_LOG_PERIOD_S:
                log.warning("%d unauthenticated connections are open: refused %d more since "
                            "the last line", self.limit, self._refused)
                self._refusal_logged, self._refused = now, 0
            return _Refused()
        return self._server()
