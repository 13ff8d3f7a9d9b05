"""The browser's wire: landscape.v1 messages in their canonical protobuf JSON, one RPC per frame.

Every WebSocket frame is a JSON object about one message of one RPC of one device:

    backend -> browser  {"device": "arm1", "rpc": "landscape.v1.DeviceService/Activate",
                         "id": 7,                       (a browser call's id; absent on feeds)
                         "reply": {"@type": "type.googleapis.com/landscape.v1.ActivateResponse",
                                   ...},                (a response message, as google.protobuf.Any)
                         "status": {"code": 9, "message": "...", "details": [ErrorInfo ...]}}
                                                        (google.rpc.Status: the call failed, or a
                                                         stream ended; code 0 = ended cleanly)
    browser -> backend  {"device": "arm1", "rpc": "landscape.v1.DeviceService/SetSpeed", "id": 8,
                         "request": {"speed": 50, "attribute": "SPEED_TYPE_PERCENT_SPEED"}}
                        ("requests": [...] for a client-streaming RPC; "cancel": true ends a stream
                         the browser opened: the session, a jog. Every frame of a stream carries
                         the id of its first: a jog press's frames share one, and each press has
                         a fresh id, larger than any before it: console.py. A server-streaming
                         call (GetPath) is answered by a frame a reply, then a status, code 0)

The feeds the backend keeps for every browser arrive under their own RPC names
(StateService/StreamState, EventService/Subscribe, the read-only gets of the status, and
DeviceService/GetCellDescription, the cell around the arm: device_hub.py).
Nothing here is a second schema: "reply" and "status" are protobuf's own JSON mapping.

Beside the contract, the supervisor's own calls among the people signed in to it (control
handed over: supervisor_calls.py) use the same frames under names
"supervisor/<Name>", with plain JSON objects as their "request" and "reply" (`note`).
"""
from __future__ import annotations

import json

import grpc
from google.protobuf import any_pb2, json_format
from google.protobuf.message import Message
from google.rpc import code_pb2, error_details_pb2, status_pb2  # noqa: F401 (ErrorInfo for JSON)


def message_dict(message: Message) -> dict:
    """Canonical JSON of a message; fields at their default value are written out too (still
    canonical), so the page never guesses what an absent field means."""
    return json_format.MessageToDict(message, always_print_fields_with_no_presence=True)


def any_dict(message: Message) -> dict:
    """The message packed in a google.protobuf.Any, as JSON: its fields plus "@type"."""
    packed = any_pb2.Any()
    packed.Pack(message)
    return message_dict(packed)


def status(code: grpc.StatusCode, message: str) -> status_pb2.Status:
    return status_pb2.Status(code=code.value[0], message=message)


class Refused(Exception):
    """A browser's frame the backend answers with this status itself: no device was called."""

    def __init__(self, code: grpc.StatusCode, message: str):
        super().__init__(message)
        self.status = status(code, message)


def frame(device: str, rpc: str, *, reply: Message | None = None,
          status: status_pb2.Status | None = None, call_id: int | None = None) -> str:
    """One backend-to-browser frame as text (see the module docstring)."""
    body: dict = {"device": device, "rpc": rpc}
    if call_id is not None:
        body["id"] = call_id
    if reply is not None:
        body["reply"] = any_dict(reply)
    if status is not None:
        body["status"] = message_dict(status)
    return json.dumps(body, separators=(",", ":"))


def note(device: str, rpc: str, body: dict, call_id: int | None = None) -> str:
    """A frame of the supervisor's own ("supervisor/<Name>"), its reply a plain JSON object."""
    frame_body: dict = {"device": device, "rpc": rpc, "reply": body}
    if call_id is not None:
        frame_body["id"] = call_id
    return json.dumps(frame_body, separators=(",", ":"))


def parse_request(message_class: type[Message], body: dict | None) -> Message:
    """A request message from its JSON; json_format.ParseError names what is wrong."""
    return json_format.ParseDict(body or {}, message_class())
