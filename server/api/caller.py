"""Who the call being handled is, for the servicers that name their caller in what they
publish (AcknowledgeAlarm): as the security layer found it, else (no security layer: tokens,
audit and rate limits all off) the peer's address and what its identity headers say.
"""
from __future__ import annotations

from contextvars import ContextVar
from dataclasses import dataclass

from landscape.server.security.auth import front_end


@dataclass(frozen=True)
class Caller:
    who: str                 # the token's name; with tokens off the peer (or its certificate)
    client: str = ""         # landscape-client: recorded, never trusted
    on_behalf_of: str = ""   # landscape-on-behalf-of: recorded, never trusted


# Set by the security layer (interceptor.py) for the call's task.
CALLER: ContextVar[Caller | None] = ContextVar("caller", default=None)


def caller_of(context) -> Caller:
    caller = CALLER.get()
    if caller is not None:
        return caller
    return Caller(context.peer(), *front_end(context.invocation_metadata()))
