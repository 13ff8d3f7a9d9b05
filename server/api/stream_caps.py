"""Caps on the streams one client may keep open, so nobody can crowd out the others.

Streams cost no thread on the asyncio server, but each holds memory and a share of the event
loop. A client may hold at most `per_client` streams of a kind, and the server at most
`total`. Sessions are a kind of their own: they carry the lock's safety, so subscriptions can
never use up the room sessions need.

A client is who the security layer says (security.py, which counts its rate limit the same
way): its token's identity where tokens are on, else its IP address and the name its
`landscape-client` header gives; without the security layer, its IP address (`client_of`).
Never a connection, which anyone can multiply.
"""
from __future__ import annotations

import threading
from collections import Counter
from contextvars import ContextVar
from dataclasses import dataclass

from landscape.server.errors import ResourceExhausted

# Which kind of stream each streaming RPC is.
KINDS = {"Connect": "session", "Jog": "session", "Subscribe": "watch", "StreamState": "watch"}


@dataclass(frozen=True)
class Cap:
    per_client: int
    total: int


# A client may be several programs (a cell's gateway, supervisor and tools share one address).
DEFAULT_CAPS = {"session": Cap(per_client=32, total=512),
                "watch": Cap(per_client=256, total=20_000)}

# Who the call being handled counts against, set by the security layer.
CLIENT: ContextVar[str | None] = ContextVar("client", default=None)


def peer_address(peer: str) -> str:
    """gRPC's peer without its port: 'ipv4:10.0.0.5:51234' -> 'ipv4:10.0.0.5',
    'ipv6:[::1]:51234' -> 'ipv6:[::1]'; any other kind (a unix socket) as it is."""
    kind, _, rest = peer.partition(":")
    if kind in ("ipv4", "ipv6") and ":" in rest:
        return f"{kind}:{rest.rsplit(':', 1)[0]}"
    return peer


def client_of(peer: str) -> str:
    """Who the call being handled counts against: as the security layer said, else its
    address."""
    client = CLIENT.get()
    return client if client is not None else peer_address(peer)


class StreamLimits:
    def __init__(self, caps: dict[str, Cap] | None = None):
        self.caps = dict(caps or DEFAULT_CAPS)
        self._open: Counter = Counter()      # (kind, client) and (kind, None) -> open streams
        self._lock = threading.Lock()

    def acquire(self, rpc: str, client: str) -> "Slot | None":
        """A slot for a new `rpc` stream of `client` (client_of); ResourceExhausted beyond
        the caps."""
        kind = KINDS.get(rpc)
        if kind is None:
            return None
        cap = self.caps[kind]
        with self._lock:
            if self._open[kind, client] >= cap.per_client:
                raise ResourceExhausted(f"this client holds {cap.per_client} {kind} streams, "
                                        f"the most one client may: close one first")
            if self._open[kind, None] >= cap.total:
                raise ResourceExhausted(f"{cap.total} {kind} streams are open, the most this "
                                        f"server takes")
            self._open[kind, client] += 1
            self._open[kind, None] += 1
        return Slot(self, kind, client)

    def open(self, kind: str, client: str | None = None) -> int:
        return self._open[kind, client]

    def release(self, kind: str, client: str) -> None:
        """A stream of `kind` that `client` held ended (Slot.release)."""
        with self._lock:
            self._open[kind, client] -= 1
            self._open[kind, None] -= 1
            if not self._open[kind, client]:
                del self._open[kind, client]


class Slot:
    def __init__(self, limits: StreamLimits, kind: str, client: str):
        self._limits, self._kind, self._client = limits, kind, client
        self._held = True

    def release(self) -> None:
        if self._held:
            self._held = False
            self._limits.release(self._kind, self._client)
