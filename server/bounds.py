"""Bounds on what a request may carry: every string and every repeated field, checked before
anything is stored or published (types.proto says the same to clients).

A string is at most `STRING` characters and a repeated field at most `REPEATED` values, unless
`FIELDS` names another bound for it. A longer string is INVALID_ARGUMENT, a longer list
OUT_OF_RANGE, and either names the field, so one client can never make the device keep, or
send to every subscriber, more than a known amount.
"""
from __future__ import annotations

from google.protobuf.descriptor import FieldDescriptor

from landscape.server.errors import OutOfRange, ParamError

STRING = 256       # characters
REPEATED = 64      # values

# Fields with bounds of their own: "Message.field" -> bound.
FIELDS = {
    "SendCommandRequest.input": 4096,
    "SetDigitalIORequest.description": 1024,
    "GetDigitalIORequest.description": 1024,
    "RsvpAnswer.data": 16,
    "PathLoadRequest.tags": 10_000,      # per message of the stream; a path: MAX_POINTS
    "TagStruct.joint_values": 24,        # the seed's own bound
    "TagStruct.aux_commands": 16,
}


def check(message, _prefix: str = "") -> None:
    """Raise naming the first field of `message` (and of its sub-messages) beyond its bound."""
    for field, value in message.ListFields():
        key = f"{field.containing_type.name}.{field.name}"
        name = f"{_prefix}{field.name}"
        if field.is_repeated:
            bound = FIELDS.get(key, REPEATED)
            if len(value) > bound:
                raise OutOfRange(f"{name} holds {len(value)} values; at most {bound}",
                                 field=name, bound=str(bound))
            items = value
        else:
            items = (value,)
        if field.type == FieldDescriptor.TYPE_STRING:
            # A repeated field's own bound counts its values; each of them is a STRING.
            bound = STRING if field.is_repeated \
                else FIELDS.get(key, STRING)
            for item in items:
                if len(item) > bound:
                    raise ParamError(f"{name} is {len(item)} characters long; at most {bound}",
                                     field=name, bound=str(bound))
        elif field.type == FieldDescriptor.TYPE_MESSAGE:
            for index, item in enumerate(items):
                check(item, f"{name}[{index}]." if field.is_repeated else f"{name}.")
