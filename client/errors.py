"""One exception vocabulary for clients, mapped once from gRPC statuses by tables.

Two families, as a caller needs to tell them apart (after Spot SDK's client exceptions):

- `CommandRefused`: the device server answered and said no (wrong state, no lock, bad or out
  of range parameter, not built). Retrying the same call changes nothing; its `reason` and
  `ret_code` are the server's google.rpc.ErrorInfo (domain "landscape"), `ret_code` being the
  seed's retVal (section 5: -1 CMD_ERR, -2 CMD_PARAM_ERR, -3 CMD_PARAM_OUT_OF_RANGE_ERR).
- `TransportError`: the call did not get an answer from the device (server down, network,
  deadline). `RetryableTransportError` may succeed if tried again; the others will not.

Commands that run on after their RPC (moves, paths) end in `CommandFailed` / `CommandAborted`
when their final event says so, or `CommandTimeout` when the caller stops waiting.

`SessionEnded`: the device ended this client's session (its keep-alives stopped arriving, the
server stopped); it stopped the arm and released the lock the session held. Every later call
that needed the lock raises it, with the server's reason, until the program opens a new
session: nothing takes the lock back by itself.
"""
from __future__ import annotations

import grpc
from google.protobuf import any_pb2
from google.rpc import error_details_pb2, status_pb2
from grpc_status import rpc_status

DOMAIN = "landscape"


class LandscapeError(Exception):
    """Base of every error this client raises."""


# ---- the server said no ---------------------------------------------------------------------

class CommandRefused(LandscapeError):
    """The device server refused the call; nothing changed (the contract's promise)."""

    def __init__(self, message: str, code: grpc.StatusCode, reason: str = "",
                 ret_code: int = -1, metadata: dict[str, str] | None = None, rpc: str = ""):
        super().__init__(message)
        self.message = message
        self.code = code              # the gRPC status code
        self.reason = reason          # ErrorInfo.reason, e.g. "WRONG_STATE" ("" if none)
        self.ret_code = ret_code      # the seed's retVal, negative
        self.metadata = metadata or {}
        self.rpc = rpc                # the call refused, e.g. "MoveAbsolute" ("" if unknown)

    def __str__(self) -> str:
        return f"{self.message} ({self.reason or self.code.name})"


class WrongState(CommandRefused):
    """Not valid in the device's current state (FAILED_PRECONDITION, WRONG_STATE)."""


class EstopActive(WrongState):
    """The e-stop is pressed; release it, then Reset."""


class NotLockHolder(CommandRefused):
    """A mutating call without this session's lease (PERMISSION_DENIED)."""


class NotAllowed(CommandRefused):
    """The caller's role token does not allow the call: none or unknown (UNAUTHENTICATED), or
    a role too low for it (PERMISSION_DENIED, ROLE_TOO_LOW): a viewer commanding, an operator
    at the panel."""


class InvalidArgument(CommandRefused):
    """A parameter is malformed: the seed's CMD_PARAM_ERR (INVALID_ARGUMENT)."""


class OutOfRange(CommandRefused):
    """A parameter is out of range: CMD_PARAM_OUT_OF_RANGE_ERR (OUT_OF_RANGE)."""


class Unreachable(OutOfRange):
    """A target or path the arm cannot follow; metadata may say where."""


class NotFound(CommandRefused):
    """No such path, tool or sensor (NOT_FOUND)."""


class NotImplementedByServer(CommandRefused):
    """The contract has the command but this device server does not carry it out yet."""


class ControllerError(CommandRefused):
    """The controller did not do what was asked in time (ABORTED, CONTROLLER)."""


class ResourceExhausted(CommandRefused):
    """Too many streams, or a message too large (RESOURCE_EXHAUSTED)."""


class ServerError(CommandRefused):
    """The server failed unexpectedly (INTERNAL, UNKNOWN); its log has the details."""


# ---- the transport failed -------------------------------------------------------------------

class TransportError(LandscapeError):
    """No answer from the device server."""

    def __init__(self, message: str, code: grpc.StatusCode, rpc: str = ""):
        super().__init__(message)
        self.message = message
        self.code = code
        self.rpc = rpc                # the call that got no answer ("" if unknown)


class RetryableTransportError(TransportError):
    """May work if tried again: the server is starting, restarting or briefly unreachable."""


class ServerUnavailable(RetryableTransportError):
    """Cannot reach the device server (UNAVAILABLE)."""


class RpcTimeout(RetryableTransportError):
    """The call's deadline passed before an answer (DEADLINE_EXCEEDED)."""


class PersistentTransportError(TransportError):
    """Will not work by retrying: cancelled, or refused credentials."""


# ---- commands that run on after their RPC ---------------------------------------------------

class CommandFailed(LandscapeError):
    """A started command ended without reaching its goal. `event` is its final event
    (landscape.v1.Event), `alarm` the alarm that names it, if one came (landscape.v1.Alarm)."""

    def __init__(self, message: str, event=None, alarm=None):
        super().__init__(message)
        self.event, self.alarm = event, alarm


class CommandAborted(CommandFailed):
    """A started command was stopped and dropped (AbortMotion, or the disconnect handler)."""


class CommandTimeout(LandscapeError):
    """A started command did not end within the time the caller waited (it may still run)."""


class EventsMissed(LandscapeError):
    """The event stream lost events (the client fell behind), so a command's end is unknown."""


class SessionEnded(LandscapeError):
    """The device ended this client's session, for `reason` (its own words, e.g. "no keep-alive
    for 2 s"); if the session held the lock, the device stopped the arm, turned the drives off
    and released it (seed 2.2). Open a new session to go on."""

    def __init__(self, reason: str, code: grpc.StatusCode | None = None,
                 held_lock: bool = False):
        self.message = f"your session ended: {reason}" + (
            "; the device stopped the arm, turned the drives off and released the lock"
            if held_lock else "")
        super().__init__(self.message)
        self.reason, self.code, self.held_lock = reason, code, held_lock


# ---- the tables -----------------------------------------------------------------------------

# ErrorInfo.reason (domain "landscape") -> exception; the server's errors.py names these.
REFUSED_BY_REASON: dict[str, type[CommandRefused]] = {
    "WRONG_STATE": WrongState,
    "ESTOP_ACTIVE": EstopActive,
    "NOT_LOCK_HOLDER": NotLockHolder,
    "UNAUTHENTICATED": NotAllowed,
    "ROLE_TOO_LOW": NotAllowed,
    "PARAM_ERR": InvalidArgument,
    "PARAM_OUT_OF_RANGE": OutOfRange,
    "UNREACHABLE": Unreachable,
    "NOT_FOUND": NotFound,
    "UNIMPLEMENTED": NotImplementedByServer,
    "CONTROLLER": ControllerError,
}

# Status code -> exception, for a refusal without a known reason.
REFUSED_BY_CODE: dict[grpc.StatusCode, type[CommandRefused]] = {
    grpc.StatusCode.FAILED_PRECONDITION: WrongState,
    grpc.StatusCode.PERMISSION_DENIED: NotLockHolder,
    grpc.StatusCode.INVALID_ARGUMENT: InvalidArgument,
    grpc.StatusCode.OUT_OF_RANGE: OutOfRange,
    grpc.StatusCode.NOT_FOUND: NotFound,
    grpc.StatusCode.UNIMPLEMENTED: NotImplementedByServer,
    grpc.StatusCode.ABORTED: ControllerError,
    grpc.StatusCode.RESOURCE_EXHAUSTED: ResourceExhausted,
    grpc.StatusCode.INTERNAL: ServerError,
    grpc.StatusCode.UNKNOWN: ServerError,
    grpc.StatusCode.ALREADY_EXISTS: CommandRefused,
}

# Status code -> exception, when no answer came from the device.
TRANSPORT_BY_CODE: dict[grpc.StatusCode, type[TransportError]] = {
    grpc.StatusCode.UNAVAILABLE: ServerUnavailable,
    grpc.StatusCode.DEADLINE_EXCEEDED: RpcTimeout,
    grpc.StatusCode.CANCELLED: PersistentTransportError,
    grpc.StatusCode.UNAUTHENTICATED: PersistentTransportError,
}


def from_rpc_error(error: grpc.RpcError, rpc: str = "") -> LandscapeError:
    """The exception for a failed call (grpc.RpcError or grpc.aio.AioRpcError) of `rpc`."""
    code = error.code()
    message = error.details() or code.name
    info = _error_info(error)
    if info is not None:   # the device answered with the contract's rich status
        ret_code = int(info.metadata.get("ret_code", -1))
        cls = REFUSED_BY_REASON.get(info.reason) or REFUSED_BY_CODE.get(code, CommandRefused)
        return cls(message, code, info.reason, ret_code, dict(info.metadata), rpc)
    if code in TRANSPORT_BY_CODE:
        return TRANSPORT_BY_CODE[code](message, code, rpc)
    return REFUSED_BY_CODE.get(code, CommandRefused)(message, code, rpc=rpc)


def _error_info(error) -> error_details_pb2.ErrorInfo | None:
    try:
        status = rpc_status.from_call(error)
    except (ValueError, AttributeError):   # a status without rich details, or no call
        return None
    for detail in status.details if status else ():
        info = error_details_pb2.ErrorInfo()
        if detail.Unpack(info) and info.domain == DOMAIN:
            return info
    return None


def to_status(error: LandscapeError) -> status_pb2.Status:
    """The google.rpc.Status an error stands for, as the device sent it (code, message, the
    ErrorInfo with its reason and the seed's ret_code), for a program that passes refusals on
    (the web supervisor's page). Errors without a gRPC code are UNKNOWN."""
    code = getattr(error, "code", None) or grpc.StatusCode.UNKNOWN
    status = status_pb2.Status(code=code.value[0],
                               message=getattr(error, "message", None) or str(error))
    if isinstance(error, CommandRefused) and error.reason:
        detail = any_pb2.Any()
        detail.Pack(error_details_pb2.ErrorInfo(reason=error.reason, domain=DOMAIN,
                                                metadata=error.metadata))
        status.details.append(detail)
    return status
