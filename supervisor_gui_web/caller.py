"""Calls to a device on someone's behalf: a view of a grpc.aio channel whose every call
carries that caller's metadata.

The metadata (identity.md): `landscape-client: supervisor`, `landscape-on-behalf-of: <who>`,
and, where the devices use tokens, `authorization: Bearer <token>`: the signed-in person's
own role token for what a person does, the supervisor's viewer token for the feeds every
browser shares. One channel per device serves everyone; the token rides on each call, so
the device's roles decide and its audit names the person.

    person = CallerChannel(link_channel, identity_metadata("alice", alice_token))
    await DeviceServiceStub(person).Activate(request)   # as alice
"""
from __future__ import annotations

from urllib.parse import quote

import grpc

AUTHORIZATION = "authorization"
CLIENT_KEY = "landscape-client"
ON_BEHALF_OF_KEY = "landscape-on-behalf-of"
CLIENT_NAME = "supervisor"
MAX_IDENTITY_CHARS = 128
# gRPC takes printable ASCII only in a text header: anything else (a name in another script,
# a control character) travels percent-encoded, as gRPC itself sends grpc-message.
_PRINTABLE = "".join(chr(c) for c in range(0x20, 0x7F) if chr(c) != "%")


def header_text(text: str) -> str:
    """`text` cut to MAX_IDENTITY_CHARS characters, then made a valid gRPC header value."""
    return quote(text[:MAX_IDENTITY_CHARS], safe=_PRINTABLE)


def identity_metadata(on_behalf_of: str, token: str | None) -> tuple[tuple[str, str], ...]:
    """What every call made for `on_behalf_of` carries; the token only when given."""
    metadata = [(CLIENT_KEY, CLIENT_NAME), (ON_BEHALF_OF_KEY, header_text(on_behalf_of))]
    if token:
        metadata.append((AUTHORIZATION, f"Bearer {token}"))
    return tuple(metadata)


class CallerChannel:
    """The multi-callable factories of a grpc.aio channel (what generated stubs and
    rpc_table use), each call made with `metadata` first. The newest call of each method is
    kept, so its owner can ask a stream how it ended (`last_call`)."""

    def __init__(self, channel: grpc.aio.Channel, metadata: tuple[tuple[str, str], ...]):
        self._channel = channel
        self.metadata = metadata
        self._last: dict[str, object] = {}

    def unary_unary(self, method: str, **options):
        return _Calls(self, method, self._channel.unary_unary(method, **options))

    def unary_stream(self, method: str, **options):
        return _Calls(self, method, self._channel.unary_stream(method, **options))

    def stream_unary(self, method: str, **options):
        return _Calls(self, method, self._channel.stream_unary(method, **options))

    def stream_stream(self, method: str, **options):
        return _Calls(self, method, self._channel.stream_stream(method, **options))

    def remember(self, method: str, call) -> None:
        self._last[method] = call

    def last_call(self, method: str):
        """The newest call of `method` ("/landscape.v1.SessionService/Connect") made through
        this view, or None."""
        return self._last.get(method)


class _Calls:
    def __init__(self, owner: CallerChannel, method: str, multi_callable):
        self._owner, self._method, self._multi_callable = owner, method, multi_callable

    def __call__(self, request, *, metadata=None, **options):
        call = self._multi_callable(request, metadata=(*self._owner.metadata, *(metadata or ())),
                                    **options)
        self._owner.remember(self._method, call)
        return call
