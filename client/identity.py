"""Who a call comes from, for the device server's records (never for authorisation: the token,
or the peer when tokens are off, decides what a caller may do).

Two metadata headers, set once where a front end makes its client core (the lead's
convention, shared by every front end):
- `landscape-client`: the program calling ("crcl-gateway", "supervisor", "landscape-cli", or a
  user program's client name);
- `landscape-on-behalf-of`: the person or remote peer it acts for ("crcl 10.0.0.7:51234", a
  signed-in person's name, "<os user>@<host>"); left out when the program acts for itself.

Values are UTF-8 text of at most 128 characters. gRPC carries only printable ASCII in a text
header, so every other byte, and '%', is percent-encoded (as gRPC encodes its own
grpc-message): "jörg@cell" travels as "j%C3%B6rg@cell" and a newline as "%0A", so no name
can break a header or a log line; the server decodes it with urllib.parse.unquote.
"""
from __future__ import annotations

import getpass
import socket
from dataclasses import dataclass

CLIENT_KEY = "landscape-client"
ON_BEHALF_OF_KEY = "landscape-on-behalf-of"
MAX_CHARACTERS = 128


def header_value(text: str) -> str:
    """`text`, cut to MAX_CHARACTERS, with every byte outside printable ASCII (and '%')
    percent-encoded."""
    out = []
    for byte in text[:MAX_CHARACTERS].encode("utf-8"):
        out.append(chr(byte) if 0x20 <= byte <= 0x7E and byte != 0x25 else f"%{byte:02X}")
    return "".join(out)


@dataclass(frozen=True)
class Identity:
    """The program calling, and whom it acts for ("" if for itself)."""

    client: str
    on_behalf_of: str = ""

    def metadata(self) -> tuple[tuple[str, str], ...]:
        headers = [(CLIENT_KEY, header_value(self.client))] if self.client else []
        if self.on_behalf_of:
            headers.append((ON_BEHALF_OF_KEY, header_value(self.on_behalf_of)))
        return tuple(headers)

    def acting_for(self, on_behalf_of: str) -> "Identity":
        """The same program acting for someone else (a CRCL peer, a signed-in person)."""
        return Identity(self.client, on_behalf_of)


def user_at_host() -> str:
    """"<os user>@<hostname>", whom a command-line program acts for."""
    try:
        user = getpass.getuser()
    except (KeyError, OSError):     # no name for this uid (a container)
        user = "unknown"
    return f"{user}@{socket.gethostname()}"
