"""Who may call what: per-role bearer tokens and the role each RPC needs.

Three roles, each holding the rights of the ones below it:

- viewer: read and watch (every read-only RPC, Subscribe, StreamState, reflection), and press
  the e-stop (anyone watching the cell may stop it);
- operator: open a session, lock and command (every RPC that needs the lease, and the session),
  and release the e-stop;
- admin: the rest of the operator panel (the door) and Reset.

The gRPC health service needs no token, so that probes and load balancers need no secret.

Tokens live in a folder with one file per role (`viewer.tokens`, `operator.tokens`,
`admin.tokens`): one token a line, optionally followed by a name for the audit log
(`<token> alice`); blank lines and `#` comments are skipped. A client sends its token as
`authorization: Bearer <token>`. Tokens are kept only as SHA-256 digests, compared in constant
time, and never logged.
"""
from __future__ import annotations

import enum
import hashlib
import hmac
import re
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import unquote

import grpc

from landscape.server.device import states
from landscape.server.errors import CommandError
from landscape.server.log_text import printable
from landscape.v1 import control_pb2

AUTHORIZATION = "authorization"
# What a front end says of a call (recorded, never trusted): the program calling and the
# person or remote peer it acts for (the lead's identity convention).
CLIENT_HEADER = "landscape-client"
ON_BEHALF_OF_HEADER = "landscape-on-behalf-of"
HEADER_LIMIT = 128          # characters of either kept
ROLE_FILE = "{role}.tokens"
MIN_TOKEN_LENGTH = 16
# What may stand in an HTTP/2 header value and in our files without quoting (RFC 6750 b64token).
_TOKEN = re.compile(r"[A-Za-z0-9\-._~+/]+=*")


class Role(enum.IntEnum):
    PUBLIC = 0     # no token needed (health)
    VIEWER = 1
    OPERATOR = 2
    ADMIN = 3

    @property
    def label(self) -> str:
        return self.name.lower()


class Unauthenticated(CommandError):
    """No token, or one this server does not know."""

    status, reason = grpc.StatusCode.UNAUTHENTICATED, "UNAUTHENTICATED"


class RoleTooLow(CommandError):
    """A known token whose role may not make this call."""

    status, reason = grpc.StatusCode.PERMISSION_DENIED, "ROLE_TOO_LOW"


class TokenFileError(ValueError):
    """A token folder or file that cannot be used; the message names the file and line."""


# RPCs whose state rule makes them read-only but which act on the device or its people.
# ReadAuditLog: the audit names people and what they did.
_ADMIN = {"OperatePanel", "Reset", "ReadAuditLog"}
# FetchRecording: a file off the device's disk, for those who command the cell (audited).
# AcknowledgeAlarm: no lease (anyone commanding the cell may), but audited and named.
_OPERATOR = {"Connect", "SendCommand", "Lock", "FetchRecording", "AcknowledgeAlarm"}
_PUBLIC_SERVICES = {"grpc.health.v1.Health"}
# Anyone watching the cell may stop it; releasing the e-stop is an operator's; the rest of the
# panel (the door) an admin's.
_PANEL_ROLES = {control_pb2.PANEL_ACTION_PRESS_ESTOP: Role.VIEWER,
                control_pb2.PANEL_ACTION_RELEASE_ESTOP: Role.OPERATOR}


def required_role(method: str, request=None) -> Role:
    """The role a full method name (`/package.Service/Rpc`) needs, for `request` if given.
    Methods of the contract follow the state table: read-only ones are viewer's, the lease's
    are operator's; the panel and Reset are admin's, but pressing the e-stop is a viewer's and
    releasing it an operator's. Anything unknown needs admin (fail closed)."""
    service, _, rpc = method.lstrip("/").rpartition("/")
    if rpc == "OperatePanel" and request is not None and service == "landscape.v1.DeviceService":
        return panel_role(request.action)
    if service in _PUBLIC_SERVICES:
        return Role.PUBLIC
    if service.startswith("grpc.reflection."):
        return Role.VIEWER
    if not service.startswith("landscape.v1.") or rpc not in states.RULES:
        return Role.ADMIN
    if rpc in _ADMIN:
        return Role.ADMIN
    if rpc in _OPERATOR or states.RULES[rpc].lease is not states.Lease.NONE:
        return Role.OPERATOR
    return Role.VIEWER


def panel_role(action: int) -> Role:
    """The role an OperatePanel action (PanelAction) needs."""
    return _PANEL_ROLES.get(action, Role.ADMIN)


def front_end(metadata) -> tuple[str, str]:
    """(landscape-client, landscape-on-behalf-of) of a call's metadata, printable, each cut to
    HEADER_LIMIT characters; "" where absent. gRPC carries only printable ASCII in a text
    header: UTF-8 comes percent-encoded (as gRPC's own grpc-message), and is decoded here."""
    found = {CLIENT_HEADER: "", ON_BEHALF_OF_HEADER: ""}
    for key, value in metadata or ():
        if key in found and not found[key]:
            text = value.decode("ascii", "replace") if isinstance(value, bytes) else value
            found[key] = printable(unquote(text, errors="replace"), HEADER_LIMIT)
    return found[CLIENT_HEADER], found[ON_BEHALF_OF_HEADER]


@dataclass(frozen=True)
class Identity:
    """Who is calling: a token's name and role, or (tokens off) the peer itself."""

    name: str
    role: Role

    def __str__(self) -> str:
        return f"{self.name} ({self.role.label})"


def _digest(token: str) -> bytes:
    return hashlib.sha256(token.encode()).digest()


class TokenStore:
    """The tokens of every role, as digests; `identify` finds a token's identity."""

    def __init__(self, entries: dict[bytes, Identity]):
        self._entries = entries

    @classmethod
    def load(cls, folder: str | Path) -> "TokenStore":
        """Read `<role>.tokens` for each role; a missing file gives that role no tokens, but
        at least one must exist. TokenFileError names the file and line of any problem."""
        folder = Path(folder)
        if not folder.is_dir():
            raise TokenFileError(f"{folder}: no such folder of token files")
        entries: dict[bytes, Identity] = {}
        found = False
        for role in (Role.VIEWER, Role.OPERATOR, Role.ADMIN):
            path = folder / ROLE_FILE.format(role=role.label)
            if not path.exists():
                continue
            found = True
            for name, token, where in _read(path, role):
                digest = _digest(token)
                if digest in entries:
                    raise TokenFileError(f"{where}: this token is already {entries[digest]}")
                entries[digest] = Identity(name, role)
        if not found:
            raise TokenFileError(f"{folder}: none of viewer.tokens, operator.tokens, "
                                 f"admin.tokens is there (make them with `landscape-cell tokens`)")
        return cls(entries)

    def __len__(self) -> int:
        return len(self._entries)

    def identify(self, metadata) -> Identity:
        """The identity of the `authorization: Bearer <token>` in `metadata`; Unauthenticated
        if it is missing or unknown."""
        header = next((value for key, value in metadata or () if key == AUTHORIZATION), None)
        if header is None:
            raise Unauthenticated("this server needs a token: send 'authorization: Bearer "
                                  "<token>' (viewer, operator or admin)")
        scheme, _, token = header.partition(" ")
        if scheme.lower() != "bearer" or not token:
            raise Unauthenticated("the authorization header must be 'Bearer <token>'")
        digest = _digest(token.strip())
        # Every stored digest is compared, each in constant time: how long it takes tells
        # nothing about which token, or how much of one, matched.
        match = None
        for known, identity in self._entries.items():
            if hmac.compare_digest(known, digest):
                match = identity
        if match is None:
            raise Unauthenticated("unknown token")
        return match


def _read(path: Path, role: Role):
    try:
        lines = path.read_text(encoding="utf-8").splitlines()
    except (OSError, UnicodeDecodeError) as error:
        raise TokenFileError(f"{path}: cannot read: {error}") from None
    count = 0
    for number, line in enumerate(lines, 1):
        words = line.split("#", 1)[0].split()
        if not words:
            continue
        where = f"{path}:{number}"
        token = words[0]
        if len(token) < MIN_TOKEN_LENGTH or not _TOKEN.fullmatch(token):
            raise TokenFileError(f"{where}: a token is at least {MIN_TOKEN_LENGTH} characters "
                                 f"of A-Z a-z 0-9 - . _ ~ + / (then = padding)")
        if len(words) > 2:
            raise TokenFileError(f"{where}: a line is '<token> [name]'")
        count += 1
        yield (words[1] if len(words) == 2 else f"{role.label}-{count}"), token, where

