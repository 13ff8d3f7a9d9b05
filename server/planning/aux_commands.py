"""Auxiliary commands of path points (seed 3.5.1 auxCommands), run when the arm reaches them.

The syntax is small on purpose, one command per string:

    dout <output name> <0|1>     set a digital output of the cell (names: ListDigitalIO)

Commands are parsed when the path is loaded, so a bad one fails the load with its point index.
"""
from __future__ import annotations

from dataclasses import dataclass

from landscape.server.errors import ParamError


@dataclass(frozen=True)
class DigitalOut:
    name: str
    value: bool


def parse(text: str, outputs: set[str]) -> DigitalOut:
    words = text.split()
    if len(words) == 3 and words[0] == "dout" and words[2] in ("0", "1"):
        if words[1] not in outputs:
            raise ParamError(f"aux command {text!r}: no digital output named {words[1]!r} "
                             f"(outputs: {', '.join(sorted(outputs))})")
        return DigitalOut(words[1], words[2] == "1")
    raise ParamError(f"aux command {text!r} is not understood; the syntax is 'dout <name> <0|1>'")
