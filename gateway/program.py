"""CRCLProgram files: their commands in order, with loop blocks unrolled.

LoopBlockStart / LoopBlockEnd (CRCLCommands.xsd) repeat the commands between them MaxCount
times; blocks nest, and each start needs its end with the same LoopName.
"""
from __future__ import annotations

from landscape.gateway import model as m
from landscape.gateway.errors import CrclError

MAX_EXPANDED = 1_000_000    # commands after unrolling: a bound on what one program may ask


def expand(program: m.Program) -> list[m.Command]:
    return unroll(list(program.commands))


def unroll(items: list, command_of=lambda item: item) -> list:
    """`items` (commands, or anything `command_of` maps to its command) with loops unrolled."""
    out, _ = _block(items, 0, None, command_of)
    return out


def _block(items: list, i: int, loop: str | None, command_of) -> tuple[list, int]:
    out = []
    while i < len(items):
        command = command_of(items[i])
        if isinstance(command, m.LoopBlockStart):
            body, i = _block(items, i + 1, command.loop_name, command_of)
            end = command_of(items[i])
            if end.max_count < 0:
                raise CrclError(f"LoopBlockEnd {end.loop_name!r}: MaxCount {end.max_count} is negative")
            if len(out) + len(body) * end.max_count > MAX_EXPANDED:
                raise CrclError(f"loop {end.loop_name!r} unrolls past {MAX_EXPANDED} commands")
            out += body * end.max_count
        elif isinstance(command, m.LoopBlockEnd):
            if command.loop_name != loop:
                raise CrclError(f"LoopBlockEnd {command.loop_name!r} (CommandID "
                                f"{command.command_id}) closes no open loop of that name")
            return out, i
        else:
            out.append(items[i])
        i += 1
    if loop is not None:
        raise CrclError(f"LoopBlockStart {loop!r} has no LoopBlockEnd")
    return out, i
