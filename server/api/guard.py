"""Every RPC behind the device's state table, on the server's event loop (grpc.aio).

`guarded(spec)` wraps each RPC a servicer class defines (itself, or a mixin it inherits: a
servicer grows by modules of its own):

1. Admission, on the event loop: the request's bounds (request_bounds.py), the state table
   (states.py) and the lease refuse the call (INVALID_ARGUMENT / OUT_OF_RANGE,
   FAILED_PRECONDITION / PERMISSION_DENIED) before anything happens, and the stream caps
   (limits.py) refuse a stream beyond its client's share (RESOURCE_EXHAUSTED).
2. The body runs where it belongs. Plain methods are synchronous and thin: read-only ones
   are answered on the event loop (they read memory), except those marked `@blocking` (they
   ask the controller); mutating ones run on the command threads inside `device.command`
   (one at a time), except those marked `@on_loop` (a setting: memory only), which run on
   the loop when no other command holds the turn; the immediate ones (they stop the arm: StopMotion, AbortMotion,
   Deactivate) on threads of their own, never behind another command. `async def` methods
   (the streams) run on the loop and use `Dispatch` for their device calls.
3. One error mapping: a CommandError ends the call with its status and ErrorInfo
   (errors.to_status); anything unexpected is logged with its traceback and ends as INTERNAL
   with an ErrorInfo, never UNKNOWN. Every refusal is logged in one line.

An RPC the class does not define answers UNIMPLEMENTED with its full name, after the state
check, so the state rules hold for the whole contract and nothing pretends to work.
"""
from __future__ import annotations

import asyncio
import functools
import inspect
import logging
from concurrent.futures import ThreadPoolExecutor

import grpc

from landscape.server.api import request_bounds
from landscape.server.device import states
from landscape.server.errors import CommandError, Internal, Unimplemented, to_status
from landscape.server.api.stream_caps import client_of
from landscape.server.device.states import Lease

log = logging.getLogger(__name__)

LEASE_KEY = "landscape-lease"


def lease_of(context) -> str | None:
    for key, value in context.invocation_metadata() or ():
        if key == LEASE_KEY:
            return value
    return None


def on_loop(body):
    """Marks a mutating RPC whose body never waits (it changes memory only: a setting): it
    runs on the event loop when no other command holds the turn, saving two thread hand-overs,
    else on a command thread like the others."""
    body.on_loop = True
    return body


def blocking(method=None, *, lane: str = "reads"):
    """Marks a read-only RPC whose body waits on the controller: it runs on a thread of the
    Dispatch pool named `lane` (`@blocking`, or `@blocking(lane="panel")`)."""
    def mark(body):
        body.blocking = lane
        return body
    return mark if method is None else mark(method)


class Dispatch:
    """The thread pools the bodies run on, shared by every servicer of one server. The
    operator panel (the e-stop) has a lane of its own: no slow read ever delays it. Parsing
    the messages of PathLoad streams has one thread: however many streams send, one thread at
    most competes with the event loop for the interpreter (a message not yet parsed when its
    stream is cancelled is never parsed)."""

    def __init__(self, commands: int = 16, immediate: int = 8, reads: int = 8, panel: int = 2):
        self.commands = ThreadPoolExecutor(commands, thread_name_prefix="command")
        self.immediate = ThreadPoolExecutor(immediate, thread_name_prefix="immediate")
        self.reads = ThreadPoolExecutor(reads, thread_name_prefix="read")
        self.panel = ThreadPoolExecutor(panel, thread_name_prefix="panel")
        self.parse = ThreadPoolExecutor(1, thread_name_prefix="parse")
        self.lanes = {"commands": self.commands, "immediate": self.immediate,
                      "reads": self.reads, "panel": self.panel, "parse": self.parse}
        self._in_flight = dict.fromkeys(self.lanes.values(), 0)

    async def run(self, pool: ThreadPoolExecutor, func, *args):
        self._in_flight[pool] += 1   # on the event loop only: no lock
        try:
            return await asyncio.get_running_loop().run_in_executor(pool, func, *args)
        finally:
            self._in_flight[pool] -= 1

    def in_flight(self) -> dict[str, int]:
        """Calls running or queued per lane (a queue depth of /metrics)."""
        return {name: self._in_flight[pool] for name, pool in self.lanes.items()}

    def shutdown(self) -> None:
        for pool in (self.commands, self.immediate, self.reads, self.panel, self.parse):
            pool.shutdown(wait=False, cancel_futures=True)


# Raised through the guard untouched: the call was cancelled, or it ends already.
PASSING = (asyncio.CancelledError, grpc.aio.AbortError, GeneratorExit)


async def end_call(context, rpc: str, exc: Exception, logged: bool = True) -> None:
    """End the call with the status of `exc`: a CommandError's own, else INTERNAL (logged with
    its traceback); either way one line in the log says who was refused and why (unless not
    `logged`: the caller sums such refusals up). A call the client has already left (or the
    server already ended) has no one to tell: noted, not reported as a failure."""
    if context.done():
        log.debug("%s ended while the call was over already: %r", rpc, exc)
        return
    if not isinstance(exc, CommandError):
        log.error("%s failed unexpectedly", rpc, exc_info=exc)
        exc = Internal(f"{rpc} failed inside the server: {type(exc).__name__}: {exc}")
    status = to_status(exc)
    if logged:
        log.info("refused %s from %s: %s %s: %s", rpc, context.peer(), exc.status.name,
                 exc.reason, exc.message)
    await context.abort(status.code, status.details, status.trailing_metadata)


def _missing(full_name: str):
    def body(self, request, context):
        raise Unimplemented(f"{full_name} is not implemented yet by this device server")
    body.unimplemented = True   # kept by functools.wraps: tests can list what is missing
    return body


def _unary(name: str, body):
    rule = states.RULES[name]
    read_only = rule.lease is Lease.NONE
    quick = getattr(body, "on_loop", False) and not read_only and not rule.immediate
    # A read valid in every state, by anyone: nothing to admit, no lease to look up (the
    # state machine's lock and the call's metadata cost each read microseconds, issue 31).
    unconditional = read_only and rule.states == states.ALL

    def run_command(self, request, context, lease):
        with self.device.command(name, lease):
            return body(self, request, context)

    @functools.wraps(body)
    async def unary(self, request, context):
        lease = None if unconditional else lease_of(context)
        try:
            request_bounds.check(request)
            if not unconditional:
                self.device.admit(name, lease)
            lane = getattr(body, "blocking", None)
            if read_only and lane is None:
                return body(self, request, context)
            if quick:
                with self.device.command_if_free(name, lease) as free:
                    if free:
                        return body(self, request, context)
            pool = (getattr(self.dispatch, lane) if read_only else
                    self.dispatch.immediate if rule.immediate else self.dispatch.commands)
            return await self.dispatch.run(pool, run_command, self, request, context, lease)
        except PASSING:
            raise
        except Exception as exc:
            await end_call(context, name, exc)
    return unary


def _stream(name: str, body, streaming_response: bool):
    """An async body (generator for server streams, coroutine for client streams)."""

    async def admitted(self, request, context):
        if hasattr(request, "ListFields"):
            request_bounds.check(request)   # streamed requests are checked message by message
        self.device.admit(name, lease_of(context))
        return self.limits.acquire(name, client_of(context.peer())) if streaming_response else None

    if streaming_response:
        @functools.wraps(body)
        async def generate(self, request, context):
            slot = None
            try:
                slot = await admitted(self, request, context)
                async for item in body(self, request, context):
                    yield item
            except PASSING:
                raise
            except Exception as exc:
                await end_call(context, name, exc)
            finally:
                if slot is not None:
                    slot.release()
        return generate

    @functools.wraps(body)
    async def call(self, request, context):
        try:
            await admitted(self, request, context)
            return await body(self, request, context)
        except PASSING:
            raise
        except Exception as exc:
            await end_call(context, name, exc)
    return call


def guarded(spec):
    """Class decorator for a servicer of `spec` with `device`, `dispatch` and `limits`."""
    def decorate(cls):
        for method in spec.descriptor.methods:
            body = (_defined(cls, spec.servicer_base, method.name)
                    or _missing(f"{spec.full_name}.{method.name}"))
            if inspect.isasyncgenfunction(body) or inspect.iscoroutinefunction(body):
                wrapped = _stream(method.name, body, method.server_streaming)
            elif method.client_streaming or method.server_streaming:
                wrapped = _stream(method.name, _as_async(body, method.server_streaming),
                                  method.server_streaming)
            else:
                wrapped = _unary(method.name, body)
            setattr(cls, method.name, wrapped)
        return cls
    return decorate


def _defined(cls, base: type, name: str):
    """The body `cls` or one of its mixins (servicers/*.py) defines for `name`; the generated
    `base` (whose every method answers UNIMPLEMENTED) does not count."""
    for klass in cls.__mro__:
        if klass is base:
            return None
        if name in klass.__dict__:
            return klass.__dict__[name]
    return None


def _as_async(body, streaming_response: bool):
    """A synchronous body of a streaming RPC (only `_missing` ones): raise on the loop."""
    if streaming_response:
        async def generate(self, request, context):
            body(self, request, context)
            yield None  # never reached: the body raises
        return generate

    async def call(self, request, context):
        return body(self, request, context)
    return call
