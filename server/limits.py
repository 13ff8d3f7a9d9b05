"""Caps on the streams one client may keep open, so nobody can crowd out the others.

Streams cost no thread on the asyncio server, but each holds memory and a share of the event
loop. A client (one connection, as gRPC names its peer) may hold at most `per_client` streams
of a kind, and the server at most `total`. Sessions are a kind of their own: they carry the
lock's safety, so subscriptions can never use up the room sessions need.
"""
from __future__ import annotations

import threading
from collections import Counter
from dataclasses import dataclass

from landscape.server.errors import ResourceExhausted

# Which kind of stream each streaming RPC is.
KINDS = {"Connect": "session", "Jog": "session", "Subscribe": "watch", "StreamState": "watch"}


@dataclass(frozen=True)
class Cap:
    per_client: int
    total: int


DEFAULT_CAPS = {"session": Cap(per_client=8, total=512), "watch": Cap(per_client=64, total=20_000)}


class StreamLimits:
    def __init__(self, caps: dict[str, Cap] | None = None):
        self.caps = dict(caps or DEFAULT_CAPS)
        self._open: Counter = Counter()      # (kind, peer) and (kind, None) -> open streams
        self._lock = threading.Lock()

    def acquire(self, rpc: str, peer: str) -> "Slot | None":
        """A slot for a new `rpc` stream of `peer`; ResourceExhausted beyond the caps."""
        kind = KINDS.get(rpc)
        if kind is None:
            return None
        cap = self.caps[kind]
        with self._lock:
            if self._open[kind, peer] >= cap.per_client:
                raise ResourceExhausted(f"this client holds {cap.per_client} {kind} streams, "
                                        f"the most one client may: close one first")
            if self._open[kind, None] >= cap.total:
                raise ResourceExhausted(f"{cap.total} {kind} streams are open, the most this "
                                        f"server takes")
            self._open[kind, peer] += 1
            self._open[kind, None] += 1
        return Slot(self, kind, peer)

    def open(self, kind: str, peer: str | None = None) -> int:
        return self._open[kind, peer]

    def _release(self, kind: str, peer: str) -> None:
        with self._lock:
            self._open[kind, peer] -= 1
            self._open[kind, None] -= 1
            if not self._open[kind, peer]:
                del self._open[kind, peer]


class Slot:
    def __init__(self, limits: StreamLimits, kind: str, peer: str):
        self._limits, self._kind, self._peer = limits, kind, peer
        self._held = True

    def release(self) -> None:
        if self._held:
            self._held = False
            self._limits._release(self._kind, self._peer)
