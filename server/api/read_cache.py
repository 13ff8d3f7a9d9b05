"""Replies to reads of state the server already holds, built once per version of that state.

A read's reply depends on a few things that change far less often than clients read them:
the settings (a new immutable value per change), the newest cycle (its sequence number), the
collision scene (its change count), a few strings of the device's status. `ReplyCache` keeps
the newest reply of each read with the version it was built for: a read whose version has
not changed gets the same message again, which grpc only has to serialize (GetRobotPosition:
one forward kinematics, two unit conversions and a message less per call; at 4 ms a cycle
and 32 clients reading flat out, most reads find the reply of their cycle built already).

Versions are tuples compared element by element: numbers and strings by value, anything else
(the settings) by identity, since such a value is replaced, never changed. A reply handed out
is never changed afterwards (grpc may be serializing it for another call). The cache lives
on the event loop, where the read-only bodies run (guard.py): no lock.
"""
from __future__ import annotations

import functools
from collections.abc import Callable
from typing import TypeVar

Reply = TypeVar("Reply")
_BY_VALUE = (int, float, str, bool, type(None))


def same_version(a: tuple, b: tuple) -> bool:
    if len(a) != len(b):
        return False
    for x, y in zip(a, b):   # a loop, not all() of a generator: this runs on every read
        if x is not y and not (type(x) in _BY_VALUE and type(x) is type(y) and x == y):
            return False
    return True


class ReplyCache:
    def __init__(self):
        self._replies: dict[str, tuple[tuple, object]] = {}   # read -> (version, reply)

    def reply(self, read: str, version: tuple, build: Callable[[], Reply]) -> Reply:
        """The reply of `read` at `version`: the one kept if built for it, else `build()`'s
        (kept instead; a build that raises keeps nothing)."""
        kept = self._replies.get(read)
        if kept is not None and same_version(kept[0], version):
            return kept[1]
        made = build()
        self._replies[read] = (version, made)
        return made


def by_version(version: Callable[[object], tuple]):
    """Marks a read-only body whose reply depends on `version(servicer)` only (its request
    has no fields): served from the servicer's `replies` (a ReplyCache) while that holds."""
    def mark(body):
        name = body.__name__

        @functools.wraps(body)
        def read(self, request, context):
            return self.replies.reply(name, version(self), lambda: body(self, request, context))
        return read
    return mark
