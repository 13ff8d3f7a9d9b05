"""Answer UNIMPLEMENTED, naming the command, for every RPC a servicer does not define yet.

The generated servicer base classes answer "Method not implemented!"; a client deserves to
know which command is missing. `complete(cls, spec)` fills each RPC of the service that `cls`
leaves to the base class with such an answer, so nothing pretends to work.
"""
from __future__ import annotations

import grpc


def _unimplemented(full_method: str):
    def handler(self, request_or_iterator, context: grpc.ServicerContext):
        context.abort(grpc.StatusCode.UNIMPLEMENTED,
                      f"{full_method} is not implemented yet by this device server")
    handler.__name__ = full_method.rsplit(".", 1)[-1]
    return handler


def complete(cls: type, spec) -> type:
    """Fill in the RPCs of `spec` that `cls` inherits unchanged from the generated base."""
    base = spec.servicer_base
    for method in spec.descriptor.methods:
        if getattr(cls, method.name) is getattr(base, method.name):
            setattr(cls, method.name, _unimplemented(f"{spec.full_name}.{method.name}"))
    return cls
