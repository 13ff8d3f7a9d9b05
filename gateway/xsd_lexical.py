"""XML Schema's lexical forms of CRCL's simple values, read from an element's text.

Not Python's: float("1_0") and float("infinity") are not xs:double. Each reader names the line
and element of a value it refuses.
"""
from __future__ import annotations

import math
import re


class CrclParseError(Exception):
    """A document the gateway cannot take; the message says where (line, element) and why."""


def local_name(element) -> str:
    tag = element.tag
    return tag if isinstance(tag, str) else "?"


_DOUBLE = re.compile(r"^[+-]?(\d+(\.\d*)?|\.\d+)([eE][+-]?\d+)?$")
_INTEGER = re.compile(r"^[+-]?\d+$")
INT_RANGE = (-2**31, 2**31 - 1)
LONG_RANGE = (-2**63, 2**63 - 1)


def fail(element, message: str):
    raise CrclParseError(f"line {element.sourceline}: <{local_name(element)}>: {message}")


def _text(element) -> str:
    if len(element):
        fail(element, "expected text, found child elements")
    return element.text or ""


def xs_double(element) -> float:
    text = _text(element).strip()
    if text in ("INF", "+INF", "-INF", "NaN"):
        fail(element, f"{text} is a double but not a usable value here")
    if not _DOUBLE.match(text):
        fail(element, f"{text!r} is not a number (xs:double)")
    value = float(text)
    if not math.isfinite(value):
        fail(element, f"{text[:40]!r} is beyond the range of a double")
    return value


def _integer(element, bounds) -> int:
    text = _text(element).strip()
    if not _INTEGER.match(text):
        fail(element, f"{text!r} is not an integer")
    value = int(text)
    if not bounds[0] <= value <= bounds[1]:
        fail(element, f"{value} is out of range")
    return value


def xs_int(element) -> int:
    return _integer(element, INT_RANGE)


def xs_long(element) -> int:
    return _integer(element, LONG_RANGE)


def xs_boolean(element) -> bool:
    text = _text(element).strip()
    if text not in ("true", "false", "1", "0"):
        fail(element, f"{text!r} is not a boolean (true, false, 1 or 0)")
    return text in ("true", "1")


def xs_string(element) -> str:
    return _text(element)


def xs_token(element) -> str:
    return " ".join(_text(element).split())


def fraction(element) -> float:
    value = xs_double(element)
    if not 0.0 <= value <= 1.0:
        fail(element, f"{value:g} is not a fraction from 0 to 1")
    return value


def positive(element) -> float:
    value = xs_double(element)
    if value <= 0:
        fail(element, f"{value:g} must be above 0")
    return value


def non_negative(element) -> float:
    value = xs_double(element)
    if value < 0:
        fail(element, f"{value:g} must not be negative")
    return value


def joint_number(element) -> int:
    value = xs_int(element)
    if value < 1:
        fail(element, f"joint numbers start at 1, got {value}")
    return value


def enum_of(*names: str):
    def read(element) -> str:
        value = xs_token(element)
        if value not in names:
            fail(element, f"{value!r} is not one of {', '.join(names)}")
        return value
    return read


