"""A client of the Foxglove WebSocket protocol as published (subprotocol foxglove.sdk.v1): the
server's JSON `serverInfo` and `advertise`, the client's `subscribe`, `fetchAsset`,
`getParameters` and `setParameters`, and the binary frames: message data (opcode 1: the
subscription id, u32, and the log time, u64, little-endian, then the message) and an asset
(opcode 4: the request id, u32, a status byte, 0 for found, an error's length, u32, and text,
then the asset). Written for the tests from the protocol's description, independent of the
SDK the bridge serves with."""
from __future__ import annotations

import base64
import json
import struct

import websockets.sync.client
from google.protobuf import descriptor_pb2, descriptor_pool, message_factory

SUBPROTOCOL = "foxglove.sdk.v1"


class FoxgloveClient:
    def __init__(self, port: int, timeout: float = 10.0):
        self._connection = websockets.sync.client.connect(
            f"ws://127.0.0.1:{port}", subprotocols=[SUBPROTOCOL], open_timeout=timeout)
        self.ws = self._connection.__enter__()
        self.timeout = timeout
        self.info: dict = {}
        self.channels: dict[int, dict] = {}      # id -> the advertised channel
        self._subscriptions: dict[int, dict] = {}
        self._decoders: dict[int, object] = {}
        self.pending: list = []                  # text messages not yet asked for

    def close(self) -> None:
        self._connection.__exit__(None, None, None)

    def _receive(self):
        frame = self.ws.recv(timeout=self.timeout)
        if isinstance(frame, str):
            message = json.loads(frame)
            if message["op"] == "serverInfo":
                self.info = message
            elif message["op"] == "advertise":
                self.channels.update((c["id"], c) for c in message["channels"])
            return message
        return frame

    def channel(self, topic: str) -> dict:
        while not any(c["topic"] == topic for c in self.channels.values()):
            self._receive()
        return next(c for c in self.channels.values() if c["topic"] == topic)

    def subscribe(self, topic: str) -> int:
        channel = self.channel(topic)
        sub = len(self._subscriptions) + 1
        self._subscriptions[sub] = channel
        self.ws.send(json.dumps({"op": "subscribe",
                                 "subscriptions": [{"id": sub, "channelId": channel["id"]}]}))
        return sub

    def messages(self, sub: int):
        """The decoded messages of subscription `sub`, as they come (log time ns, message)."""
        while True:
            frame = self._receive()
            if isinstance(frame, bytes) and frame[0] == 1:
                got, log_time = struct.unpack_from("<IQ", frame, 1)
                if got == sub:
                    yield log_time, self.decode(sub, frame[13:])

    def decode(self, sub: int, payload: bytes):
        channel = self._subscriptions[sub]
        if channel["encoding"] == "json":
            return json.loads(payload)
        if sub not in self._decoders:
            files = descriptor_pb2.FileDescriptorSet.FromString(
                base64.b64decode(channel["schema"]))
            pool = descriptor_pool.DescriptorPool()
            for file in files.file:
                pool.Add(file)
            self._decoders[sub] = message_factory.GetMessageClass(
                pool.FindMessageTypeByName(channel["schemaName"]))
        return self._decoders[sub].FromString(payload)

    def fetch_asset(self, uri: str, request_id: int = 1) -> tuple[int, bytes]:
        """(status, the asset or the error's text)."""
        self.ws.send(json.dumps({"op": "fetchAsset", "uri": uri, "requestId": request_id}))
        while True:
            frame = self._receive()
            if isinstance(frame, bytes) and frame[0] == 4:
                got, status, length = struct.unpack_from("<IBI", frame, 1)
                if got == request_id:
                    return status, (frame[10:10 + length] if status else frame[10 + length:])

    def parameters(self, names=(), set_values: dict | None = None) -> dict:
        if set_values is not None:
            self.ws.send(json.dumps({"op": "setParameters", "id": "set", "parameters": [
                {"name": name, "value": value} for name, value in set_values.items()]}))
        self.ws.send(json.dumps({"op": "getParameters", "parameterNames": list(names),
                                 "id": "get"}))
        while True:
            frame = self._receive()
            if isinstance(frame, dict) and frame["op"] == "parameterValues" and \
                    frame.get("id") == "get":
                return {p["name"]: p.get("value") for p in frame["parameters"]}
