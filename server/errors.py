"""One error vocabulary for the device server, mapped once to gRPC statuses.

Domain code raises a `CommandError` subclass; `ErrorMappingInterceptor` turns it into a status
whose google.rpc.ErrorInfo (domain "landscape") carries a reason and, in metadata["ret_code"],
the seed's return code (section 5), so any client can recover the seed's retVal.
"""
from __future__ import annotations

import logging

import grpc
from google.protobuf import any_pb2
from google.rpc import error_details_pb2, status_pb2
from grpc_status import rpc_status

log = logging.getLogger(__name__)

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


class NotLockHolder(CommandError):
    status, reason = grpc.StatusCode.PERMISSION_DENIED, "NOT_LOCK_HOLDER"


class ParamError(CommandError):
    status, reason, ret_code = grpc.StatusCode.INVALID_ARGUMENT, "PARAM_ERR", CMD_PARAM_ERR


class OutOfRange(CommandError):
    status, reason, ret_code = (grpc.StatusCode.OUT_OF_RANGE, "PARAM_OUT_OF_RANGE",
                                CMD_PARAM_OUT_OF_RANGE_ERR)


class NotFound(CommandError):
    status, reason, ret_code = grpc.StatusCode.NOT_FOUND, "NOT_FOUND", CMD_PARAM_ERR


class ControllerFailure(CommandError):
    """The controller did not do what was asked in time (e.g. enabling timed out)."""

    status, reason = grpc.StatusCode.ABORTED, "CONTROLLER"


def to_status(error: CommandError) -> grpc.Status:
    info = error_details_pb2.ErrorInfo(
        reason=error.reason, domain=DOMAIN,
        metadata={"ret_code": str(error.ret_code), **error.metadata})
    detail = any_pb2.Any()
    detail.Pack(info)
    return rpc_status.to_status(status_pb2.Status(
        code=error.status.value[0], message=error.message, details=[detail]))


def _mapped(behavior, streaming_response: bool):
    """Wrap one RPC behaviour so a CommandError ends the call with its status."""
    if streaming_response:
        def generate(request, context):
            try:
                yield from behavior(request, context)
            except CommandError as error:
                context.abort_with_status(to_status(error))
        return generate

    def call(request, context):
        try:
            return behavior(request, context)
        except CommandError as error:
            context.abort_with_status(to_status(error))
    return call


class ErrorMappingInterceptor(grpc.ServerInterceptor):
    """Maps CommandError to statuses for every RPC, whatever its streaming shape."""

    def intercept_service(self, continuation, handler_call_details):
        handler = continuation(handler_call_details)
        if handler is None:
            return None
        for kind, factory in (("unary_unary", grpc.unary_unary_rpc_method_handler),
                              ("unary_stream", grpc.unary_stream_rpc_method_handler),
                              ("stream_unary", grpc.stream_unary_rpc_method_handler),
                              ("stream_stream", grpc.stream_stream_rpc_method_handler)):
            behavior = getattr(handler, kind)
            if behavior is not None:
                return factory(_mapped(behavior, handler.response_streaming),
                               request_deserializer=handler.request_deserializer,
                               response_serializer=handler.response_serializer)
        return handler


class Unimplemented(CommandError):
    """A command of the contract that this device server does not carry out yet."""

    status, reason = grpc.StatusCode.UNIMPLEMENTED, "UNIMPLEMENTED"


class Unreachable(OutOfRange):
    """A motion target or path the arm cannot follow (workspace, joint range, singularity);
    metadata names where (a point index or a fraction of the path) when known."""

    reason = "UNREACHABLE"
