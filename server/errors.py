"""One error vocabulary for the device server, mapped once to gRPC statuses.

Domain code raises a `CommandError` subclass; the servicers' guard (servicers/guard.py) turns it
into a status whose google.rpc.ErrorInfo (domain "landscape") carries a reason and, in
metadata["ret_code"], the seed's return code (section 5), so any client can recover the seed's
retVal. Anything else that escapes a body becomes `Internal`, never UNKNOWN.
"""
from __future__ import annotations

import grpc
from google.protobuf import any_pb2
from google.rpc import error_details_pb2, status_pb2
from grpc_status import rpc_status

DOMAIN = "landscape"

# The seed's return codes (section 5).
CMD_EXEC_OK, CMD_STARTED_OK, CMD_ERR, CMD_PARAM_ERR, CMD_PARAM_OUT_OF_RANGE_ERR = 0, 1, -1, -2, -3


class CommandError(Exception):
    """A command the device refuses or cannot carry out; nothing changed unless it says so."""

    status = grpc.StatusCode.UNKNOWN
    reason = "ERROR"
    ret_code = CMD_ERR

    def __init__(self, message: str, **metadata: str):
        super().__init__(message)
        self.message = message
        self.metadata = metadata


class WrongState(CommandError):
    status, reason = grpc.StatusCode.FAILED_PRECONDITION, "WRONG_STATE"


class EstopActive(CommandError):
    """The e-stop is pressed: release it first."""

    status, reason = grpc.StatusCode.FAILED_PRECONDITION, "ESTOP_ACTIVE"


class ManualControlMode(CommandError):
    """Jog needs manual control on; every other motion needs it off (seed 3.7.3)."""

    status, reason = grpc.StatusCode.FAILED_PRECONDITION, "MANUAL_CONTROL"


class NotLockHolder(CommandError):
    status, reason = grpc.StatusCode.PERMISSION_DENIED, "NOT_LOCK_HOLDER"


class ParamError(CommandError):
    status, reason, ret_code = grpc.StatusCode.INVALID_ARGUMENT, "PARAM_ERR", CMD_PARAM_ERR


class OutOfRange(CommandError):
    status, reason, ret_code = (grpc.StatusCode.OUT_OF_RANGE, "PARAM_OUT_OF_RANGE",
                                CMD_PARAM_OUT_OF_RANGE_ERR)


class NotFound(CommandError):
    """A name (path, tool, sensor) the device does not know: a parameter error (the seed's
    CMD_PARAM_ERR), so INVALID_ARGUMENT; the reason says NOT_FOUND."""

    status, reason, ret_code = grpc.StatusCode.INVALID_ARGUMENT, "NOT_FOUND", CMD_PARAM_ERR


class ControllerFailure(CommandError):
    """The controller did not do what was asked in time (e.g. enabling timed out)."""

    status, reason = grpc.StatusCode.ABORTED, "CONTROLLER"


def info_metadata(error: CommandError) -> dict[str, str]:
    """The ErrorInfo metadata of a refusal: its seed ret_code and what it names."""
    return {"ret_code": str(error.ret_code), **error.metadata}


def to_status(error: CommandError) -> grpc.Status:
    info = error_details_pb2.ErrorInfo(reason=error.reason, domain=DOMAIN,
                                       metadata=info_metadata(error))
    detail = any_pb2.Any()
    detail.Pack(info)
    return rpc_status.to_status(status_pb2.Status(
        code=error.status.value[0], message=error.message, details=[detail]))


class NotOffered(CommandError):
    """What this cell's controller does not offer (an optional capability of its backend,
    robot/controller.py: an operator panel, say)."""

    status, reason = grpc.StatusCode.FAILED_PRECONDITION, "NOT_OFFERED"


class Unimplemented(CommandError):
    """A command of the contract that this device server does not carry out yet."""

    status, reason = grpc.StatusCode.UNIMPLEMENTED, "UNIMPLEMENTED"


class Unreachable(OutOfRange):
    """A motion target or path the arm cannot follow (workspace, joint range, singularity);
    metadata names where (a point index or a fraction of the path) when known."""

    reason = "UNREACHABLE"


class Stopped(CommandError):
    """A session of the caller's (a jog) ended by something else than the caller: the deadman,
    a stop, the lock changing hands."""

    status, reason = grpc.StatusCode.ABORTED, "STOPPED"


class ResourceExhausted(CommandError):
    """A bound on what one client may hold (streams, sizes) was reached."""

    status, reason = grpc.StatusCode.RESOURCE_EXHAUSTED, "RESOURCE_EXHAUSTED"


class StorageFull(ResourceExhausted):
    """The disk that keeps what the call would store (paths, settings, the audit) is full:
    nothing was stored, nothing changed."""

    reason = "STORAGE_FULL"


class Unavailable(CommandError):
    """The server cannot do this now for a reason of its own that may pass (a file it cannot
    write); the message says which. Nothing changed."""

    status, reason = grpc.StatusCode.UNAVAILABLE, "UNAVAILABLE"


class StorageFailed(Unavailable):
    """What the call would store could not be written (other than a full disk)."""

    reason = "STORAGE_FAILED"


class Internal(CommandError):
    """Something failed inside the server that should not have; it is logged with its
    traceback. Nothing the call was to do should be assumed done."""

    status, reason = grpc.StatusCode.INTERNAL, "INTERNAL"


class Collision(CommandError):
    """A planned motion would bring two bodies of the cell closer than the safety margin;
    metadata names them and where (time, fraction, segment). Nothing moved."""

    status, reason = grpc.StatusCode.FAILED_PRECONDITION, "COLLISION"
