"""The security layer: one grpc.aio server interceptor in front of every servicer.

For each call, before the servicer (and so before the guard's bounds, state and lease checks,
servicers/guard.py) sees it:

1. who: the bearer token's identity (auth.py), UNAUTHENTICATED without a known one; with
   tokens off, the peer (its certificate's common name under mutual TLS), with every right.
   What its front end says (auth.front_end: `landscape-client`, `landscape-on-behalf-of`) is
   recorded, never trusted;
2. may they: the role the call needs (auth.required_role, per request: anyone may press the
   e-stop), PERMISSION_DENIED for a role too low;
3. not too often: a token bucket per client, RESOURCE_EXHAUSTED beyond it. A client is its
   token's identity, sized by its name (rate_limit.py); with tokens off, its address and its
   `landscape-client` name (the best there is without authentication: a name is only what
   the caller says), sized by that name. A call without a known token counts against its
   address. The calls that stop the arm (STOPS, the e-stop's press) are never limited. The
   client is also what the guard's stream caps count (limits.CLIENT);
4. written down (audit.py): every call that needs more than a viewer, and the operator panel.
   A call that would move the arm or change a setting runs only once its record is written
   (write-ahead): while the audit cannot write, it is refused (UNAVAILABLE). The calls that
   stop the arm, and Release, never wait for the audit: written when it can. Refused
   authentication is written once per address per interval with its count (refusal_tally.py).

The health service passes untouched: probes need no secret.

With /metrics on, it also times every unary call by method and status (`timing`, given by the
server's metrics, server/metrics.py); without, nothing is timed.
"""
from __future__ import annotations

import asyncio
import inspect
import logging
import time
from collections.abc import Callable
from collections import Counter

import grpc

from landscape.server.device import states
from landscape.server.security.audit import AuditLog, Record
from landscape.server.security.auth import (Identity, Role, RoleTooLow, TokenStore, Unauthenticated,
                                   front_end, required_role)
from landscape.server.errors import CommandError, ResourceExhausted
from landscape.server.api.caller import CALLER, Caller
from landscape.server.api.stream_caps import CLIENT, peer_address
from landscape.server.log_text import printable
from landscape.server.security.rate_limit import RateLimiter
from landscape.server.security.refusal_tally import RefusalTally
from landscape.server.api.guard import end_call
from landscape.v1 import control_pb2

log = logging.getLogger(__name__)

# The calls that stop the arm (StopMotion, AbortMotion, Deactivate) and the e-stop's press:
# never rate limited (a stop must always get through), never refused for want of an audit
# record (safety first; written when the audit can). Release, which gives control up, is
# never refused for the audit either.
STOPS = {name for name, rule in states.RULES.items() if rule.immediate}
GIVING_UP = {"Release"}
FIRST_MESSAGE_WAIT = 1.0    # s a refused request stream is given to deliver its first message


class RateLimited(ResourceExhausted):
    reason = "RATE_LIMITED"


def stops_the_arm(name: str, request) -> bool:
    """Whether the call `name` with `request` (a message, or None for a stream) stops the arm."""
    return name in STOPS or (name == "OperatePanel" and request is not None
                             and request.action == control_pb2.PANEL_ACTION_PRESS_ESTOP)


class _Call:
    """One call as the layer sees it: who, what, since when, and its audit record."""

    def __init__(self, layer: "SecurityInterceptor", method: str, role: Role, context):
        self.layer, self.method, self.context = layer, method, context
        self.name = method.rsplit("/", 1)[-1]           # "MoveAbsolute"
        self.audited = role >= Role.OPERATOR            # the method's role, whatever the request
        self.gated = False                              # must be written before it runs
        self.address = peer_address(context.peer())
        self.identity: Identity | None = None
        self.record: Record | None = None

    def admit(self, request) -> None:
        """Steps 1 to 3; a CommandError says why not. Sets what the record says."""
        layer, context = self.layer, self.context
        metadata = context.invocation_metadata()
        via, on_behalf_of = front_end(metadata)
        self.record = Record("anonymous", "-", via, on_behalf_of, context.peer(),
                             self.method.rsplit(".", 1)[-1], request)
        if layer.tokens is not None:
            try:
                self.identity = layer.tokens.identify(metadata)
            except Unauthenticated:
                self._limit(f"unauthenticated {self.address}", None)
                raise
            client, size = f"token {self.identity.name}", self.identity.name
        else:
            self.identity = Identity(_peer_name(context), Role.ADMIN)
            client, size = f"{self.address} {via}", via
        self.record.who, self.record.role = self.identity.name, self.identity.role.label
        CLIENT.set(client)      # this call's task: the guard's stream caps see it
        CALLER.set(Caller(self.identity.name, via, on_behalf_of))   # and servicers naming it
        message = request if hasattr(request, "ListFields") else None
        needs = required_role(self.method, message)
        if self.identity.role < needs:
            raise RoleTooLow(f"{self.name} needs the {needs.label} role; "
                             f"{self.identity.name} has the {self.identity.role.label} role",
                             role=self.identity.role.label, needs=needs.label)
        stop = stops_the_arm(self.name, message)
        if not stop:
            self._limit(client, size)
        self.gated = (self.audited and layer.audit is not None
                      and not (stop or self.name in GIVING_UP))

    def _limit(self, client: str, size: str | None) -> None:
        rate = self.layer.rate
        if rate is not None and not rate.allow(client, size):
            calls, burst = rate.budget(size)
            raise RateLimited(f"more than {calls:g} calls a second (bursts of {burst:g}) from "
                              f"this client: slow down")

    async def write_ahead(self, result: str) -> None:
        """The record, in the file before the call runs; AuditUnavailable if it cannot be."""
        await self.layer.audit.write_ahead(self.record, result)

    def write(self, result: str) -> None:
        if self.layer.audit is not None and self.record is not None:
            self.layer.audit.record(self.record, result)

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
        """End the call with `error`'s status, written down (refused authentication: counted
        per address, written once per interval)."""
        result = f"{error.status.name}: {error.message}"
        told = True
        if self.identity is None:
            told = self.layer.tally_refusal(self.address, error.status.name)
            if told:
                self.write(result)
        elif self.audited:
            self.write(result)
        if not hasattr(request, "ListFields"):
            # A request stream: take its first message before refusing. A grpc.aio client
            # whose first write meets an ended call reports INTERNAL instead of our status.
            try:
                await asyncio.wait_for(anext(aiter(request), None), FIRST_MESSAGE_WAIT)
            except Exception:   # gone, slow or broken: it gets the status all the same
                pass
        await end_call(self.context, self.name, error, logged=told)

    async def admitted(self, request, first: str) -> None:
        """Admission, and the write-ahead of a gated call; ends the call if refused."""
        try:
            self.admit(request)
            if self.gated:
                await self.write_ahead(first)
        except CommandError as error:
            await self.refuse(error, request)


class SecurityInterceptor(grpc.aio.ServerInterceptor):
    def __init__(self, tokens: TokenStore | None = None, audit: AuditLog | None = None,
                 rate: RateLimiter | None = None,
                 timing: Callable[[str, str, float], None] | None = None):
        """timing(method, status, seconds): each unary call's duration, if given."""
        self.tokens, self.audit, self.rate, self.timing = tokens, audit, rate, timing
        self._tally = RefusalTally(self._write_refusals)

    @property
    def idle(self) -> bool:
        """Nothing to check, limit, write or time: the server need not install it."""
        return (self.tokens is None and self.audit is None and self.rate is None
                and self.timing is None)

    def close(self) -> None:
        """Write the refusals still counted, and close the audit log."""
        self._tally.flush_all()
        if self.audit is not None:
            self.audit.close()

    def tally_refusal(self, address: str, status: str) -> bool:
        """Count a refused authentication; True if it is to be written and logged itself."""
        first = self._tally.note(address, status)
        if first:
            asyncio.get_running_loop().call_later(self._tally.interval, self._tally.flush,
                                                  address)
        return first

    def _write_refusals(self, address: str, counts: Counter, seconds: float) -> None:
        total = sum(counts.values())
        detail = ", ".join(f"{status} {n}" for status, n in counts.most_common())
        text = (f"{total} more calls without a known token refused from {address} in "
                f"{seconds:.0f} s ({detail})")
        log.warning("%s", text)
        if self.audit is not None:
            self.audit.record(Record("anonymous", "-", "", "", address, "(any)", None),
                              f"{counts.most_common(1)[0][0]}: {text}")

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
            if self.timing is not None:
                wrapped = self._timed(method, wrapped)
            make = (grpc.stream_unary_rpc_method_handler if handler.request_streaming
                    else grpc.unary_unary_rpc_method_handler)
        return make(wrapped, handler.request_deserializer, handler.response_serializer)

    def _unary(self, method: str, role: Role, behavior):
        async def call(request, context):
            record = _Call(self, method, role, context)
            await record.admitted(request, "ADMITTED")
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

    def _timed(self, method: str, behavior):
        name, timing = method.rsplit("/", 1)[-1], self.timing

        async def call(request, context):
            started, failure = time.perf_counter(), None
            try:
                return await behavior(request, context)
            except BaseException as exc:
                failure = exc
                raise
            finally:
                timing(name, status_name(context, _unexpected(failure)),
                       time.perf_counter() - started)
        return call

    def _streaming(self, method: str, role: Role, behavior):
        async def stream(request, context):
            record = _Call(self, method, role, context)
            await record.admitted(request, "OPEN")
            failure = None
            try:
                if record.audited and not record.gated:
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


def status_name(context, failure: BaseException | None) -> str:
    """The status a call ended with: its context's (an abort), else OK or how it failed."""
    code = context.code()
    if code is not None and code != grpc.StatusCode.OK and code != 0:
        return code.name if isinstance(code, grpc.StatusCode) else str(code)
    if failure is None:
        return "OK"
    return "CANCELLED" if isinstance(failure, asyncio.CancelledError) else "UNKNOWN"


def _unexpected(exc: BaseException | None) -> BaseException | None:
    """An exception that is not an abort (whose status the context holds)."""
    return None if isinstance(exc, grpc.aio.AbortError) else exc


def _peer_name(context) -> str:
    """The client's certificate common name under mutual TLS, else its address."""
    names = (context.auth_context() or {}).get("x509_common_name")
    return printable(names[0].decode(errors="replace")) if names else context.peer()
