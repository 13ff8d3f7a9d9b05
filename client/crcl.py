"""Run a CRCL program (NIST's Canonical Robot Command Language) through a CRCL gateway.

The wire is as NIST's reference client uses it (see shared/crcl/README.md): TCP (default
port 64444), UTF-8 XML documents back to back with no framing. A program's commands
(InitCanon, each MiddleCommand, EndCanon) are sent one at a time, each as its own
CRCLCommandInstance; after each, GetStatus is polled about every 100 ms until the status
names that command as CRCL_Done (next) or CRCL_Error (stop, with its StateDescription).
"""
from __future__ import annotations

import socket
import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from typing import Callable

XSI = "http://www.w3.org/2001/XMLSchema-instance"
XSI_TYPE = f"{{{XSI}}}type"
DEFAULT_PORT = 64444
POLL_PERIOD = 0.1   # seconds between GetStatus polls, as the reference client
STATUS_END = b"</CRCLStatus>"

ET.register_namespace("xsi", XSI)


class CrclError(Exception):
    """The program is not CRCL, the gateway is unreachable, or a command ended in CRCL_Error."""


@dataclass(frozen=True)
class CrclCommand:
    command_id: int
    type: str          # e.g. "MoveToType"
    element: ET.Element


def read_program(text: str | bytes) -> list[CrclCommand]:
    """The commands of a CRCLProgram document, in order."""
    try:
        root = ET.fromstring(text)
    except ET.ParseError as error:
        raise CrclError(f"not XML: {error}") from None
    if root.tag != "CRCLProgram":
        raise CrclError(f"the root element is {root.tag}, not CRCLProgram")
    commands = []
    for child in root:
        kind = {"InitCanon": "InitCanonType", "EndCanon": "EndCanonType"}.get(child.tag)
        kind = kind or child.get(XSI_TYPE)
        if child.tag not in ("InitCanon", "EndCanon", "MiddleCommand") or not kind:
            raise CrclError(f"unexpected element {child.tag} in CRCLProgram")
        command_id = child.findtext("CommandID")
        if command_id is None or not command_id.strip().isdigit():
            raise CrclError(f"{child.tag} ({kind}) has no numeric CommandID")
        commands.append(CrclCommand(int(command_id), kind, child))
    return commands


def command_instance(kind: str, body: ET.Element | None = None, command_id: int = 0) -> bytes:
    """One CRCLCommandInstance document: the command `kind` with `body`'s children."""
    root = ET.Element("CRCLCommandInstance")
    command = ET.SubElement(root, "CRCLCommand", {XSI_TYPE: kind})
    if body is None:
        ET.SubElement(command, "CommandID").text = str(command_id)
    else:
        command.extend(list(body))
    return ET.tostring(root, encoding="utf-8", xml_declaration=True)


@dataclass(frozen=True)
class CrclStatus:
    command_id: int
    state: str          # CRCL_Done, CRCL_Error, CRCL_Working, CRCL_Ready
    description: str


def parse_status(document: bytes) -> CrclStatus:
    root = ET.fromstring(document)
    status = root.find("CommandStatus")
    if status is None:
        raise CrclError("a CRCLStatus without CommandStatus")
    return CrclStatus(int(status.findtext("CommandID", "0")), status.findtext("CommandState", ""),
                      status.findtext("StateDescription", "") or "")


class CrclConnection:
    """A TCP connection to a CRCL gateway."""

    def __init__(self, host: str, port: int = DEFAULT_PORT, timeout: float = 10.0):
        try:
            self._sock = socket.create_connection((host, port), timeout=timeout)
        except OSError as error:
            raise CrclError(f"cannot reach the CRCL gateway at {host}:{port}: "
                            f"{error.strerror or error}") from None
        self._buffer = b""
        self._status_id = 1_000_000   # GetStatus ids, apart from the program's

    def close(self) -> None:
        self._sock.close()

    def __enter__(self) -> "CrclConnection":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def send(self, document: bytes) -> None:
        self._sock.sendall(document)

    def status(self) -> CrclStatus:
        self._status_id += 1
        self.send(command_instance("GetStatusType", command_id=self._status_id))
        while STATUS_END not in self._buffer:
            chunk = self._sock.recv(65536)
            if not chunk:
                raise CrclError("the CRCL gateway closed the connection")
            self._buffer += chunk
        end = self._buffer.index(STATUS_END) + len(STATUS_END)
        document, self._buffer = self._buffer[:end], self._buffer[end:].lstrip()
        return parse_status(document)

    def run(self, command: CrclCommand, timeout: float) -> CrclStatus:
        """Send one command and poll until the status names it Done (returned) or Error."""
        self.send(command_instance(command.type, command.element))
        deadline = time.monotonic() + timeout
        while True:
            status = self.status()
            if status.command_id == command.command_id:
                if status.state == "CRCL_Done":
                    return status
                if status.state == "CRCL_Error":
                    raise CrclError(f"command {command.command_id} ({command.type}) failed: "
                                    f"{status.description or 'CRCL_Error'}")
            if time.monotonic() > deadline:
                raise CrclError(f"command {command.command_id} ({command.type}) did not finish "
                                f"within {timeout} s (last status {status.state})")
            time.sleep(POLL_PERIOD)


def run_program(text: str | bytes, host: str, port: int = DEFAULT_PORT,
                command_timeout: float = 60.0,
                on_done: Callable[[CrclCommand, CrclStatus], None] | None = None) -> int:
    """Run every command of the program; returns how many ran. Raises CrclError."""
    commands = read_program(text)
    with CrclConnection(host, port) as connection:
        for command in commands:
            status = connection.run(command, command_timeout)
            if on_done is not None:
                on_done(command, status)
    return len(commands)
