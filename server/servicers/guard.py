"""Put every RPC of a servicer behind the device's state table (states.py).

`guarded(spec)` wraps each RPC the class defines in `device.command(rpc, lease)`, which refuses
it (FAILED_PRECONDITION / PERMISSION_DENIED) before anything happens; an RPC the class does not
define yet is guarded the same way and then answers UNIMPLEMENTED with its full name, so the
state rules hold for the whole contract from the start and nothing pretends to work.
"""
from __future__ import annotations

import functools

from landscape.server.errors import Unimplemented

LEASE_KEY = "landscape-lease"


def lease_of(context) -> str | None:
    for key, value in context.invocation_metadata() or ():
        if key == LEASE_KEY:
            return value
    return None


def _missing(full_name: str):
    def body(self, request, context):
        raise Unimplemented(f"{full_name} is not implemented yet by this device server")
    return body


def _wrap(name: str, body, streaming: bool):
    if streaming:
        @functools.wraps(body)
        def stream(self, request, context):
            with self.device.command(name, lease_of(context)):
                yield from body(self, request, context)
        return stream

    @functools.wraps(body)
    def unary(self, request, context):
        with self.device.command(name, lease_of(context)):
            return body(self, request, context)
    return unary


def guarded(spec):
    """Class decorator for a servicer of `spec` that has a `device` attribute."""
    def decorate(cls):
        for method in spec.descriptor.methods:
            body = cls.__dict__.get(method.name) or _missing(f"{spec.full_name}.{method.name}")
            setattr(cls, method.name, _wrap(method.name, body, method.server_streaming))
        return cls
    return decorate
