"""A forwarding gRPC proxy between the gateway and a real device server, for tests: every
landscape.v1 call passes through unchanged (bytes, metadata, status and its details), counted
per method with their metadata, and a method's stream can be held (its messages wait) to
play a stalled link.

It is no stand-in for a component: the device server answers every call; the proxy only
watches and, when told, delays."""
from __future__ import annotations

import collections
import threading
from concurrent import futures

import grpc

from landscape.v1 import (crcl_service_pb2, device_service_pb2, digital_io_service_pb2,
                          event_service_pb2, session_service_pb2, state_service_pb2)

_SKIPPED_METADATA = ("user-agent", "grpc-")


def _methods() -> dict[str, tuple[bool, bool]]:
    """'/package.Service/Method' -> (client streams, server streams), from the descriptors."""
    out = {}
    for module in (crcl_service_pb2, device_service_pb2, digital_io_service_pb2,
                   event_service_pb2, session_service_pb2, state_service_pb2):
        for service in module.DESCRIPTOR.services_by_name.values():
            for method in service.methods:
                out[f"/{service.full_name}/{method.name}"] = (method.client_streaming,
                                                              method.server_streaming)
    return out


class GrpcProxy:
    def __init__(self, target: str):
        self.channel = grpc.insecure_channel(target)
        self.calls: collections.Counter[str] = collections.Counter()   # method name -> calls
        self.metadata: list[tuple[str, dict]] = []    # (method name, its metadata), in order
        self._held: dict[str, threading.Event] = {}   # method -> cleared while held
        self._methods = _methods()
        self.server = grpc.server(futures.ThreadPoolExecutor(max_workers=64))
        self.server.add_generic_rpc_handlers([_Handler(self)])
        self.port = self.server.add_insecure_port("127.0.0.1:0")
        self.target = f"127.0.0.1:{self.port}"
        self.server.start()

    def hold(self, method: str) -> None:
        """Messages of `method`'s response streams ("StreamState") wait until release()."""
        self._held.setdefault(method, threading.Event()).clear()

    def release(self, method: str) -> None:
        self._held.setdefault(method, threading.Event()).set()

    def count(self, *methods: str) -> int:
        return sum(self.calls[m] for m in methods) if methods else sum(self.calls.values())

    def close(self) -> None:
        for gate in self._held.values():
            gate.set()
        self.server.stop(None)
        self.channel.close()

    def _wait_gate(self, method: str, context) -> None:
        gate = self._held.get(method)
        while gate is not None and not gate.wait(0.05):
            if not context.is_active():
                return


class _Handler(grpc.GenericRpcHandler):
    def __init__(self, proxy: GrpcProxy):
        self.proxy = proxy

    def service(self, details):
        kind = self.proxy._methods.get(details.method)
        if kind is None:
            return None
        proxy, path = self.proxy, details.method
        name = path.rsplit("/", 1)[1]
        client_streams, server_streams = kind
        upstream = getattr(proxy.channel, {(False, False): "unary_unary",
                                           (False, True): "unary_stream",
                                           (True, False): "stream_unary",
                                           (True, True): "stream_stream"}[kind])(path)

        def metadata(context):
            kept = [(k, v) for k, v in context.invocation_metadata()
                    if not k.startswith(_SKIPPED_METADATA)]
            proxy.metadata.append((name, dict(kept)))
            return kept

        def fail(error: grpc.RpcError, context):
            context.set_trailing_metadata(error.trailing_metadata() or ())
            context.abort(error.code(), error.details() or "")

        def unary(request, context):
            proxy.calls[name] += 1
            try:
                return upstream(request, metadata=metadata(context))
            except grpc.RpcError as error:
                fail(error, context)

        def streaming(request, context):
            proxy.calls[name] += 1
            call = upstream(request, metadata=metadata(context))
            context.add_callback(call.cancel)
            try:
                # The headers as the device sends them: a subscriber waits for them (it is
                # registered then) before the first event.
                context.send_initial_metadata(call.initial_metadata())
                for reply in call:
                    proxy._wait_gate(name, context)
                    yield reply
            except grpc.RpcError as error:
                if context.is_active():
                    fail(error, context)

        handler = streaming if server_streams else unary
        make = {(False, False): grpc.unary_unary_rpc_method_handler,
                (False, True): grpc.unary_stream_rpc_method_handler,
                (True, False): grpc.stream_unary_rpc_method_handler,
                (True, True): grpc.stream_stream_rpc_method_handler}[(client_streams,
                                                                        server_streams)]
        return make(handler)
