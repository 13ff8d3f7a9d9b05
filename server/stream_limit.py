"""A cap on open server streams, so they cannot take every worker thread from the commands.

Each open stream (session, event subscription, jog) holds one of the server's worker threads
for as long as it lasts. Beyond `max_streams` a new stream is refused at once with
RESOURCE_EXHAUSTED; unary commands always find a worker free.
"""
from __future__ import annotations

import threading

import grpc


class StreamLimitInterceptor(grpc.ServerInterceptor):
    def __init__(self, max_streams: int):
        self.max_streams = max_streams
        self._slots = threading.BoundedSemaphore(max_streams)

    def intercept_service(self, continuation, handler_call_details):
        handler = continuation(handler_call_details)
        if handler is None or not handler.response_streaming:
            return handler
        kind = "stream_stream" if handler.request_streaming else "unary_stream"
        behavior = getattr(handler, kind)

        def limited(request, context):
            if not self._slots.acquire(blocking=False):
                context.abort(grpc.StatusCode.RESOURCE_EXHAUSTED,
                              f"{self.max_streams} streams are open, the most this server "
                              f"takes; close one first")
            try:
                yield from behavior(request, context)
            finally:
                self._slots.release()

        factory = getattr(grpc, f"{kind}_rpc_method_handler")
        return factory(limited, request_deserializer=handler.request_deserializer,
                       response_serializer=handler.response_serializer)
