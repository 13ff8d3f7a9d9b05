"""Run a CRCLProgram file against a CRCL gateway, as NIST's reference client does: each
command in its own CRCLCommandInstance, then GetStatus polls until it is Done or Error.
Prints progress per command; stops at the first error, printing its description.

    python -m landscape.gateway.run program.xml --gateway 127.0.0.1:64444
    landscape-crcl-run program.xml
"""
from __future__ import annotations

import argparse
import copy
import socket
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from lxml import etree

from landscape.gateway import model as m
from landscape.gateway import parse, xmlsafe
from landscape.gateway.program import unroll
from landscape.gateway.wire import Document, DocumentSplitter

XSI = "http://www.w3.org/2001/XMLSchema-instance"


class ProgramFailed(Exception):
    """A command ended in CRCL_Error (or the gateway went away); the text says which and why."""


# What a run may raise: the program failed, the gateway is unreachable, the file is not CRCL.
FAILURES = (ProgramFailed, OSError, xmlsafe.XmlRefused, parse.CrclParseError)


def instances(path: Path) -> list[tuple[m.Command, bytes]]:
    """Each command of the program (loops unrolled) as a CRCLCommandInstance document."""
    tree = xmlsafe.parse(path.read_bytes(), max_size=64 << 20)
    program = parse.program(tree.getroot())
    elements = [e for e in tree.getroot() if e.tag in ("InitCanon", "MiddleCommand", "EndCanon")]
    pairs = unroll(list(zip(program.commands, elements)), command_of=lambda pair: pair[0])
    out = []
    for index, (command, element) in enumerate(pairs):
        root = etree.Element("CRCLCommandInstance", nsmap={"xsi": XSI})
        body = copy.deepcopy(element)
        body.tag = "CRCLCommand"
        body.set(f"{{{XSI}}}type", f"{command.KIND}Type")
        root.append(body)
        for tag, value in (("ProgramFile", path.name), ("ProgramIndex", index),
                           ("ProgramLength", len(pairs))):
            etree.SubElement(root, tag).text = str(value)
        out.append((command, etree.tostring(root, xml_declaration=True, encoding="UTF-8")))
    return out


class Client:
    def __init__(self, address: str, timeout: float):
        host, port = address.rsplit(":", 1)
        try:
            self.sock = socket.create_connection((host.strip("[]"), int(port)), timeout=timeout)
        except OSError as error:
            raise ProgramFailed(f"cannot reach the CRCL gateway at {address}: "
                                f"{error.strerror or error}") from None
        self.splitter = DocumentSplitter()
        self.pending: list[bytes] = []

    def send(self, data: bytes) -> None:
        self.sock.sendall(data)

    def close(self) -> None:
        self.sock.close()

    def status(self, command_id: int) -> tuple[int, str, str]:
        """(CommandID, CommandState, StateDescription) from a GetStatus."""
        self.send(_get_status(command_id))
        while not self.pending:
            data = self.sock.recv(65536)
            if not data:
                raise ProgramFailed("the gateway closed the connection")
            self.pending += [d.data for d in self.splitter.feed(data) if isinstance(d, Document)]
        root = xmlsafe.parse(self.pending.pop(0)).getroot()
        return (int(root.findtext("CommandStatus/CommandID")),
                root.findtext("CommandStatus/CommandState"),
                root.findtext("CommandStatus/StateDescription") or "")


def _get_status(command_id: int) -> bytes:
    return (f'<?xml version="1.0" encoding="UTF-8"?><CRCLCommandInstance xmlns:xsi="{XSI}">'
            f'<CRCLCommand xsi:type="GetStatusType"><CommandID>{command_id}</CommandID>'
            f'</CRCLCommand></CRCLCommandInstance>').encode()


@dataclass(frozen=True)
class Progress:
    """One command of a program run, as it ended."""

    index: int            # 0-based, in the program with its loops unrolled
    total: int
    kind: str             # e.g. "MoveTo"
    command_id: int
    state: str            # CRCL_Done or CRCL_Error
    description: str
    seconds: float

    def __str__(self) -> str:
        return (f"[{self.index + 1}/{self.total}] {self.kind} (CommandID {self.command_id}): "
                f"{self.state} in {self.seconds:.3f} s"
                f"{' - ' + self.description if self.description else ''}")


def run(path: Path, address: str, poll: float = 0.005, timeout: float = 300.0,
        report: Callable[[Progress], None] | None = None, out=sys.stdout) -> int:
    """Runs the program; returns how many commands were done. Raises ProgramFailed (and
    OSError, xmlsafe.XmlRefused, parse.CrclParseError). `report` gets each command's Progress
    (default: printed to `out`)."""
    report = report or (lambda progress: print(progress, file=out, flush=True))
    commands = instances(path)
    client = Client(address, timeout)
    try:
        return _run(client, commands, poll, timeout, report)
    finally:
        client.close()         # its session ends now, failed or not: the lock is free


def _run(client: Client, commands, poll: float, timeout: float, report) -> int:
    """Each command in turn, to its end; ProgramFailed at the first error."""
    for index, (command, document) in enumerate(commands):
        started = time.monotonic()
        client.send(document)
        if isinstance(command, m.GetStatus):
            _, state, description = client.status(command.command_id)
        else:
            while True:
                command_id, state, description = client.status(command.command_id)
                if command_id == command.command_id and state in ("CRCL_Done", "CRCL_Error"):
                    break
                if time.monotonic() - started > timeout:
                    raise ProgramFailed(f"command {index} ({command.KIND}, CommandID "
                                        f"{command.command_id}): not done in {timeout:g} s")
                time.sleep(poll)
        report(Progress(index, len(commands), command.KIND, command.command_id, state,
                        description, time.monotonic() - started))
        if state == "CRCL_Error":
            raise ProgramFailed(f"command {index} ({command.KIND}, CommandID "
                                f"{command.command_id}) failed: {description}")
    return len(commands)


def main(argv=None) -> None:
    parser = argparse.ArgumentParser(prog="landscape-crcl-run", description=__doc__,
                                     formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("program", type=Path, help="a CRCLProgram file")
    parser.add_argument("--gateway", default="127.0.0.1:64444", help="the CRCL gateway")
    parser.add_argument("--poll", type=float, default=0.005, help="seconds between status polls")
    parser.add_argument("--timeout", type=float, default=300.0, help="seconds per command")
    args = parser.parse_args(argv)
    try:
        count = run(args.program, args.gateway, args.poll, args.timeout)
    except FAILURES as error:
        print(f"program failed: {error}", file=sys.stderr)
        sys.exit(1)
    print(f"program done: {count} commands")


if __name__ == "__main__":
    main()
