"""The value types a cell configuration's tables share (config.py, bridge_tables.py): names,
addresses, ports, paths from the file's folder, and the devices a front end shows."""
from __future__ import annotations

import re
from pathlib import Path
from typing import Annotated

from pydantic import PlainValidator, ValidationInfo

from landscape.robot.toml_tables import integer, number, problem

_NAME = re.compile(r"[A-Za-z][A-Za-z0-9_-]{0,31}")


def _name(value):
    if not isinstance(value, str) or not _NAME.fullmatch(value):
        raise problem(f"expected a name: a letter, then letters, digits, - or _ (at most 32 in "
                      f"all); got {value!r}")
    return value


def _text(value):
    """A string, empty or not."""
    if not isinstance(value, str):
        raise problem(f"expected a string, got {value!r}")
    return value


def _strip(value):
    if not isinstance(value, str) or not value:
        raise problem(f"expected an address (a non-empty string), got {value!r}")
    return value.strip("[]") if value.startswith("[") else value


def path_value(value, info: ValidationInfo):
    """A path, relative ones from the file's folder; "" is the key's default."""
    if value == "":
        return None
    if not isinstance(value, str):
        raise problem(f"expected a path (a string), got {value!r}")
    path = Path(value).expanduser()
    return path if path.is_absolute() else info.context["base"] / path


def exists(path: Path | None, key: str = "", folder: bool = False) -> None:
    if path is not None and not path.exists():
        raise problem(f"{path} does not exist", key)
    if folder and path is not None and not path.is_dir():
        raise problem(f"{path} is not a folder", key)


Name = Annotated[str, PlainValidator(_name)]
Text = Annotated[str, PlainValidator(_text)]
Address = Annotated[str, PlainValidator(_strip)]
Port = integer(0, 65535)
FilePath = Annotated[Path | None, PlainValidator(path_value)]
Positive = number(above=0.0)


def shown_devices(shown, names: list[str], key: str) -> tuple[str, ...]:
    """The devices a bridge shows (None: all), each named in the cell."""
    shown = names if shown is None else shown
    if not shown or not all(isinstance(n, str) for n in shown):
        raise problem(f"expected a non-empty list of device names, got {shown!r}", key)
    for name in shown:
        if name not in names:
            raise problem(f"no device is named {name!r} (devices: {', '.join(names)})", key)
    return tuple(dict.fromkeys(shown))
