"""A descriptor pool for server reflection that also resolves method names.

protobuf's upb-based pool answers FindFileContainingSymbol for services and messages but not
for "package.Service.Method", which `grpcurl describe` asks for; we fall back to the file of
the service.
"""
from __future__ import annotations

from google.protobuf import descriptor_pool


class MethodResolvingPool:
    def __init__(self, pool=None):
        self._pool = pool or descriptor_pool.Default()

    def FindFileContainingSymbol(self, symbol: str):  # noqa: N802 (protobuf's name)
        try:
            return self._pool.FindFileContainingSymbol(symbol)
        except KeyError:
            service, _, method = symbol.rpartition(".")
            if not service:
                raise
            found = self._pool.FindServiceByName(service).FindMethodByName(method)
            if found is None:
                raise
            return found.containing_service.file

    def __getattr__(self, name):
        return getattr(self._pool, name)
