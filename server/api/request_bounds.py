"""Bounds on what a request may carry: every string and every repeated field, checked before
anything is stored or published (types.proto says the same to clients).

A string is at most `STRING` characters and a repeated field at most `REPEATED` values, unless
`FIELDS` names another bound for it. A longer string is INVALID_ARGUMENT, a longer list
OUT_OF_RANGE, and either names the field, so one client can never make the device keep, or
send to every subscriber, more than a known amount.
"""
from __future__ import annotations

import functools

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


def check(message) -> None:
    """Raise naming the first field of `message` (and of its sub-messages) beyond its bound."""
    found = _beyond(message)
    if found is None:
        return
    name, size, bound, text = found
    if text:
        raise ParamError(f"{name} is {size} characters long; at most {bound}",
                         field=name, bound=str(bound))
    raise OutOfRange(f"{name} holds {size} values; at most {bound}", field=name, bound=str(bound))


def _beyond(message) -> tuple[str, int, int, bool] | None:
    """The first field beyond its bound: (its path, its size, the bound, whether the size is a
    string's) or None. Names are only made for the one found (a PathLoad message carries
    10,000 sub-messages)."""
    for name, repeated, count_bound, string_bound, nested in _fields(message.DESCRIPTOR):
        if nested and not repeated:
            if message.HasField(name) and (found := _beyond(getattr(message, name))):
                return (f"{name}.{found[0]}", *found[1:])
            continue
        value = getattr(message, name)
        if repeated:
            if len(value) > count_bound:
                return name, len(value), count_bound, False
            if string_bound is not None:
                for item in value:
                    if len(item) > string_bound:
                        return name, len(item), string_bound, True
            elif nested:
                for index, item in enumerate(value):
                    if found := _beyond(item):
                        return (f"{name}[{index}].{found[0]}", *found[1:])
        elif string_bound is not None and len(value) > string_bound:
            return name, len(value), string_bound, True
    return None


@functools.cache
def _fields(descriptor) -> tuple:
    """The fields of a message type that have bounds, in field number order: (name, repeated,
    bound on its count, bound on each string or None, is a message)."""
    out = []
    for field in sorted(descriptor.fields, key=lambda f: f.number):
        repeated = field.is_repeated
        text = field.type == FieldDescriptor.TYPE_STRING
        nested = field.type == FieldDescriptor.TYPE_MESSAGE
        if not (repeated or text or nested):
            continue
        key = f"{descriptor.name}.{field.name}"
        # A repeated field's own bound counts its values; each of them is a STRING.
        string_bound = (STRING if repeated else FIELDS.get(key, STRING)) if text else None
        out.append((field.name, repeated, FIELDS.get(key, REPEATED), string_bound, nested))
    return tuple(out)
