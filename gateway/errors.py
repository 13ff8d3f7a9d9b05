"""The gateway's error for a CRCL command it cannot carry out, and how the client core's
errors read in a CRCL status."""
from __future__ import annotations

import contextlib

from landscape.client.errors import CommandRefused, LandscapeError, NotImplementedByServer

# The device's reasons for refusing a motion before anything moved (ErrorInfo.reason).
_BEFORE_MOVING = {"UNREACHABLE": "is out of the arm's reach",
                  "PARAM_OUT_OF_RANGE": "is out of a joint's range", "COLLISION": ""}


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


@contextlib.contextmanager
def refused_before_moving(point: str = ""):
    """A motion the device refuses as out of reach, out of a joint's range or colliding
    becomes a CrclError saying so first, and that nothing moved; `point` names what the
    device's point index counts ("waypoint": a path's points after its start)."""
    try:
        yield
    except CommandRefused as refused:
        why = _BEFORE_MOVING.get(refused.reason)
        if why is None:
            raise
        index = refused.metadata.get("index")
        which = f"{point} {index}" if point and index else "the target"
        said = f"{which} {why}" if why else "the motion would collide"
        raise CrclError(f"{said}, nothing moved: {refused.message}") from None
