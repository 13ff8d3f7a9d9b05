"""The gateway's error for a CRCL command it cannot carry out, and how the client core's
errors read in a CRCL status."""
from __future__ import annotations

from landscape.client.errors import CommandRefused, LandscapeError, NotImplementedByServer


class CrclError(Exception):
    """A command that cannot be carried out; the text becomes its StateDescription."""


def describe(error: CrclError | LandscapeError) -> str:
    """A failure as a StateDescription; a device's: which call, the device's code and reason,
    and its own explanation."""
    if isinstance(error, NotImplementedByServer):
        return f"the device does not implement {error.rpc or 'it'} yet (UNIMPLEMENTED): " \
               f"{error.message}"
    if isinstance(error, CommandRefused):
        reason = f"/{error.reason}" if error.reason else ""
        return f"{error.rpc or 'a call'} refused by the device ({error.code.name}{reason}): " \
               f"{error.message}"
    return str(error)
