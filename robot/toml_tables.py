"""TOML files read into typed tables (pydantic v2 models): the pieces the cell file
(sim/cell.py) and the cell configuration (cell/config.py) share.

Every error names the file, the key and what was expected, one line each:
`cell.toml: devices[1].port: expected an integer from 0 to 65535, got 'x'`. Values are taken
as TOML has them, strictly: a number is a TOML integer or float (never a boolean or a string of
digits), an integer an integer, a string a non-empty string. A table refuses unknown keys,
naming the ones it knows, so a typo never falls back to a default. A check across keys raises
`problem(message, key)`, the key relative to the table it checks.
"""
from __future__ import annotations

import math
import tomllib
from typing import Annotated, Any, Callable, Sequence

from pydantic import BaseModel, ConfigDict, PlainValidator, ValidationError, model_validator
from pydantic_core import PydanticCustomError

__all__ = ["Table", "problem", "read_toml", "number", "integer", "string", "flag", "vector",
           "names"]


def problem(message: str, key: str = "") -> PydanticCustomError:
    """The error of a table's check, at `key` below the table ("": the table itself)."""
    return PydanticCustomError("toml", "{message}", {"message": message, "key": key})


class Table(BaseModel):
    """A TOML table: frozen; unknown keys are refused, naming the keys it knows."""

    model_config = ConfigDict(frozen=True, extra="forbid")

    @model_validator(mode="before")
    @classmethod
    def _known_keys(cls, data: Any) -> Any:
        if not isinstance(data, dict):
            raise problem(f"expected a table, got {data!r}")
        unknown = sorted(set(data) - set(cls.model_fields))
        if unknown:
            raise problem(f"unknown key (known here: {', '.join(sorted(cls.model_fields))})",
                          unknown[0])
        return data

    def given(self, key: str) -> bool:
        """Whether the file set `key` (not its default)."""
        return key in self.model_fields_set


def read_toml(text: str, model: type[Table], source: str, error: type[Exception],
              context: dict | None = None) -> Any:
    """`model` of TOML text; `error` (an exception class) with one line per problem, each
    naming `source` and the key. `context` reaches the validators (ValidationInfo.context)."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise error(f"{source}: not valid TOML: {exc}") from None
    try:
        return model.model_validate(data, context=context)
    except ValidationError as exc:
        raise error("\n".join(f"{source}: {_where(e)}: {_message(e)}"
                              for e in exc.errors(include_url=False))) from None


def _where(e: dict) -> str:
    where = ""
    for part in e["loc"]:
        where += f"[{part}]" if isinstance(part, int) else f".{part}"
    key = (e.get("ctx") or {}).get("key", "")
    if key:
        where += key if key.startswith("[") else f".{key}"
    return where.lstrip(".") or "(top level)"


# pydantic's own errors of the tables' structure, said as the rest are
_STRUCTURE = {"missing": "is required", "list_type": "expected an array of tables ([[...]])",
              "dict_type": "expected a table", "model_type": "expected a table"}


def _message(e: dict) -> str:
    if e["type"] in _STRUCTURE:
        return _STRUCTURE[e["type"]] + ("" if e["type"] == "missing" else f", got {e['input']!r}")
    return e["msg"]


# ---- values -----------------------------------------------------------------------------------

def _bounds(low, high, above) -> str:
    if low is not None and high is not None:
        return f" from {low:g} to {high:g}"
    lower = (f"above {above:g}" if above is not None else
             f"of at least {low:g}" if low is not None else "")
    upper = "" if high is None else ("and at most" if lower else "of at most") + f" {high:g}"
    return "".join(f" {part}" for part in (lower, upper) if part)


def _is_number(v) -> bool:
    return not isinstance(v, bool) and isinstance(v, (int, float)) and math.isfinite(v)


def number(low: float | None = None, high: float | None = None, *, above: float | None = None,
           then: Callable[[float], float] | None = None) -> Any:
    """A finite number within [low, high], or above `above`; read as a float, then passed
    through `then` if given (its ValueError is the key's error)."""
    what = "a number" + _bounds(low, high, above)

    def check(v):
        if (not _is_number(v) or (above is not None and v <= above)
                or (low is not None and v < low) or (high is not None and v > high)):
            raise problem(f"expected {what}, got {v!r}")
        if then is None:
            return float(v)
        try:
            return then(float(v))
        except ValueError as error:
            raise problem(str(error)) from None
    return Annotated[float, PlainValidator(check)]


def integer(low: int | None = None, high: int | None = None) -> Any:
    """An integer within [low, high]."""
    what = "an integer" + _bounds(low, high, None)

    def check(v):
        if (isinstance(v, bool) or not isinstance(v, int) or (low is not None and v < low)
                or (high is not None and v > high)):
            raise problem(f"expected {what}, got {v!r}")
        return v
    return Annotated[int, PlainValidator(check)]


def string(choices: Sequence[str] | None = None) -> Any:
    """A non-empty string, one of `choices` if given."""
    def check(v):
        if choices is not None and v not in choices:
            raise problem(f"expected one of {', '.join(choices)}; got {v!r}")
        if not isinstance(v, str) or not v:
            raise problem(f"expected a non-empty string, got {v!r}")
        return v
    return Annotated[str, PlainValidator(check)]


def _flag(v):
    if not isinstance(v, bool):
        raise problem(f"expected true or false, got {v!r}")
    return v


flag = Annotated[bool, PlainValidator(_flag)]


def vector(n: int, *, positive: bool = False) -> Any:
    """A list of n finite numbers (positive ones if asked); read as a tuple of floats."""
    what = f"a list of {n} {'positive ' if positive else ''}numbers"

    def check(v):
        if (not isinstance(v, list) or len(v) != n or not all(map(_is_number, v))
                or (positive and min(v) <= 0)):
            raise problem(f"expected {what}, got {v!r}")
        return tuple(float(x) for x in v)
    return Annotated[tuple[float, ...], PlainValidator(check)]


def names(items: Sequence, what: str, key: str) -> None:
    """A problem at `key` if two of `items` (with a .name) share their name."""
    seen: set[str] = set()
    for item in items:
        if item.name in seen:
            raise problem(f"two {what} are named {item.name!r}", key)
        seen.add(item.name)
