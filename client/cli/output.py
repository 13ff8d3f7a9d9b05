"""How the CLI prints: for people by default, JSON for scripts (`--json`).

Human output is short lines on stdout; progress and errors go to stderr. In JSON mode every
result is one JSON document on stdout (streams print one document per line, JSON Lines) and
an error is one JSON document on stderr.
"""
from __future__ import annotations

import datetime
import json
import sys
from typing import Any

import click
from google.protobuf import json_format
from google.protobuf.message import Message

from landscape.client.values import AngularUnit, DeviceState, LinearUnit


def to_dict(message: Message) -> dict:
    """A reply as plain JSON-able data: proto field names, every field (defaults included)."""
    return json_format.MessageToDict(message, preserving_proto_field_name=True,
                                     always_print_fields_with_no_presence=True)


class Output:
    def __init__(self, as_json: bool):
        self.as_json = as_json

    def result(self, data: dict, human: str) -> None:
        """One command's result."""
        click.echo(json.dumps(data) if self.as_json else human)

    def reply(self, message: Message) -> None:
        """A blocking command's reply: its ret_msg for people, the whole reply for scripts."""
        data = to_dict(message)
        ret_msg = data.get("ret_val", {}).get("ret_msg", "")
        fields = {k: v for k, v in data.items() if k != "ret_val"}
        lines = [ret_msg] if ret_msg else []
        lines += [f"{key}: {_human_value(value)}" for key, value in fields.items()]
        self.result(data, "\n".join(lines) or "done")

    def note(self, text: str) -> None:
        """Something for people only (never on stdout in JSON mode)."""
        click.echo(text, err=self.as_json)


def _human_value(value: Any) -> str:
    if isinstance(value, list):
        return " ".join(_number(v) for v in value)
    if isinstance(value, dict):
        return "  ".join(f"{k} {_number(v)}" for k, v in value.items())
    return _number(value)


def _number(value: Any) -> str:
    return f"{value:.4f}" if isinstance(value, float) else str(value)


def state_name(value: int) -> str:
    return DeviceState(value).name if value else "UNSPECIFIED"


def units_names(units) -> dict:
    """{"linear": "meters", "angular": "radians"} from a landscape.v1 Units."""
    return {"linear": LinearUnit(units.linear).name.lower() if units.linear else "",
            "angular": AngularUnit(units.angular).name.lower() if units.angular else ""}


def event_line(event) -> str:
    """One event for people: sequence, local time, the seed's event id and data."""
    when = datetime.datetime.fromtimestamp(event.time.ToNanoseconds() / 1e9).strftime("%H:%M:%S.%f")
    return f"#{event.sequence} {when[:-3]} {event.event_id} {' '.join(event.data)}".rstrip()


def sample_line(sample) -> str:
    joints = " ".join(f"{q:.4f}" for q in sample.joint_positions)
    p = sample.tool_pose
    return (f"{state_name(sample.device_state)} joints [{joints}] tool [{p.x:.4f} {p.y:.4f} "
            f"{p.z:.4f} | {p.roll:.4f} {p.pitch:.4f} {p.yaw:.4f}] {sample.motion_control_state}")


def show_error(payload: dict, human: str, as_json: bool) -> None:
    click.echo(json.dumps({"error": payload}) if as_json else f"error: {human}", err=True)


def stderr_is_terminal() -> bool:
    return sys.stderr.isatty()
