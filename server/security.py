"""The security layer: one grpc.aio server interceptor in front of every servicer.

For each call, before the servicer (and so before the guard's bounds, state and lease checks,
servicers/guard.py) sees it:

1. who: the bearer token's identity (auth.py), UNAUTHENTICATED without a known one; with
   tokens off, the peer (its certificate's common name under mutual TLS), with every right;
2. may they: the method's role (auth.required_role), PERMISSION_DENIED for a role too low;
3. not too often: a token bucket per client (rate_limit.py; a client is its token's identity,
   else its IP address: limits.client_of), RESOURCE_EXHAUSTED beyond it; the calls that stop
   the arm are never limited. The identity is also what the guard's stream caps count;
4. written down: every call that needs more than a viewer, and every refused token, goes to
   the audit log (audit.py) with its result.

The health service passes untouched: probes need no secret.
"""
from __future__ import annotations

import asyncio
import inspect
import logging
import time

import grpc

from landscape.server import states
from landscape.server.audit import AuditLog, describe
from landscape.server.auth import Identity, Role, RoleTooLow, TokenStore, required_role
from landscape.server.errors import CommandError, ResourceExhausted
from landscape.server.limits import TOKEN_IDENTITY, client_of
from landscape.server.rate_limit import RateLimiter
from landscape.server.servicers.guard import end_call

log = logging.getLogger(__name__)

# Calls that make the arm safe: never rate limited (a stop must always get through).
UNLIMITED = {name for name, rule in states.RULES.items() if rule.immediate} | {"OperatePanel"}
FIRST_MESSAGE_WAIT = 1.0    # s a refused request stream is given to deliver its first message


class RateLimited(ResourceExhausted):
    reason = "RATE_LIMITED"


class _Call:
    """One call as the layer sees it: who, what, since when, and its audit record."""

    def __init__(self, layer: "SecurityInterceptor", method: str, role: Role, context):
        self.layer, self.method, self.role, self.context = layer, method, role, context
        self.rpc = method.rsplit(".", 1)[-1]            # "DeviceService/MoveAbsolute"
        self.name = method.rsplit("/", 1)[-1]           # "MoveAbsolute"
        self.started, self.wall = time.monotonic(), time.time()
        self.identity: Identity | None = None
        self.request = None        # described only if written down

    def admit(self, request) -> None:
        """Steps 1 to 3; a CommandError says why not."""
        self.request = request
        layer, context = self.layer, self.context
        if layer.tokens is not None:
            self.identity = layer.tokens.identify(context.invocation_metadata())
            TOKEN_IDENTITY.set(self.identity.name)   # this call's task: the guard sees it
        else:
            self.identity = Identity(_peer_name(context), Role.ADMIN)
        if self.identity.role < self.role:
            raise RoleTooLow(f"{self.name} needs the {self.role.label} role; "
                             f"{self.identity.name} is a {self.identity.role.label}",
                             role=self.identity.role.label, needs=self.role.label)
        if layer.rate is not None and self.name not in UNLIMITED:
            if not layer.rate.allow(client_of(context.peer())):
                raise RateLimited(f"more than {layer.rate.rate:g} calls a second (bursts of "
                                  f"{layer.rate.burst}) from this client: slow down")

    @property
    def audited(self) -> bool:
        return self.role >= Role.OPERATOR

    def write(self, result: str) -> None:
        audit = self.layer.audit
        if audit is None:
            return
        who = self.identity.name if self.identity else "anonymous"
        role = self.identity.role.label if self.identity else "-"
        audit.record(who=who, role=role, peer=self.context.peer(), rpc=self.rpc,
                     request=describe(self.request), result=result, started=self.started,
                     wall=self.wall)

    def outcome(self, exc: BaseException | None = None) -> str:
        """The call's result: the status it ended with, else how it ended."""
        code = self.context.code()
        if code is not None and code != grpc.StatusCode.OK and code != 0:
            name = code.name if isinstance(code, grpc.StatusCode) else str(code)
            details = self.context.details() or ""
            return f"{name}: {details}" if details else name
        if exc is None:
            return "OK"
        if isinstance(exc, (asyncio.CancelledError, GeneratorExit)):
            return "CANCELLED: the client left"
        return f"INTERNAL: {type(exc).__name__}: {exc}"

    async def refuse(self, error: CommandError, request) -> None:
        if self.audited or self.identity is None:
            self.write(f"{error.status.name}: {error.message}")
        if not hasattr(request, "ListFields"):
            # A request stream: take its first message before refusing. A grpc.aio client
            # whose first write meets an ended call reports INTERNAL instead of our status.
            try:
                await asyncio.wait_for(anext(aiter(request), None), FIRST_MESSAGE_WAIT)
            except Exception:   # gone, slow or broken: it gets the status all the same
                pass
        await end_call(self.context, self.name, error)


class SecurityInterceptor(grpc.aio.ServerInterceptor):
    def __init__(self, tokens: TokenStore | None = None, audit: AuditLog | None = None,
                 rate: RateLimiter | None = None):
        self.tokens, self.audit, self.rate = tokens, audit, rate

    @property
    def idle(self) -> bool:
        """Nothing to check, limit or write: the server need not install it."""
        return self.tokens is None and self.audit is None and self.rate is None

    async def intercept_service(self, continuation, handler_call_details):
        handler = await continuation(handler_call_details)
        method = handler_call_details.method
        role = required_role(method)
        if handler is None or role is Role.PUBLIC:
            return handler
        if handler.response_streaming:
            wrapped = self._streaming(method, role, handler.stream_stream
                                      if handler.request_streaming else handler.unary_stream)
            make = (grpc.stream_stream_rpc_method_handler if handler.request_streaming
                    else grpc.unary_stream_rpc_method_handler)
        else:
            wrapped = self._unary(method, role, handler.stream_unary
                                  if handler.request_streaming else handler.unary_unary)
            make = (grpc.stream_unary_rpc_method_handler if handler.request_streaming
                    else grpc.unary_unary_rpc_method_handler)
        return make(wrapped, handler.request_deserializer, handler.response_serializer)

    def _unary(self, method: str, role: Role, behavior):
        async def call(request, context):
            record = _Call(self, method, role, context)
            try:
                record.admit(request)
            except CommandError as error:
                await record.refuse(error, request)
            failure = None
            try:
                reply = behavior(request, context)
                return await reply if inspect.isawaitable(reply) else reply
            except BaseException as exc:
                failure = exc
                raise
            finally:
                if record.audited:
                    record.write(record.outcome(_unexpected(failure)))
        return call

    def _streaming(self, method: str, role: Role, behavior):
        async def stream(request, context):
            record = _Call(self, method, role, context)
            try:
                record.admit(request)
            except CommandError as error:
                await record.refuse(error, request)
            failure = None
            try:
                if record.audited:
                    record.write("OPEN")
                result = behavior(request, context)
                if inspect.isasyncgen(result):
                    async for item in result:
                        yield item
                else:
                    await result
            except BaseException as exc:
                failure = exc
                raise
            finally:
                if record.audited:
                    record.write(record.outcome(_unexpected(failure)))
        return stream


def _unexpected(exc: BaseException | None) -> BaseException | None:
    """An exception that is not an abort (whose status the context holds)."""
    return None if isinstance(exc, grpc.aio.AbortError) else exc


def _peer_name(context) -> str:
    """The client's certificate common name under mutual TLS, else its address."""
    names = (context.auth_context() or {}).get("x509_common_name")
    return names[0].decode(errors="replace") if names else context.peer()
