"""The records of the device's event stream (seed section 2, DESIGN 8), mirroring
landscape.v1 event_service.proto: a command's phases, alarms, state changes, digital-I/O
signals, RSVP questions and answers, operator messages, acknowledged alarms, and lost events. Pure Python; the bus
(events.py) numbers and fans them out, convert.py puts them on the wire.
"""
from __future__ import annotations

import enum
from dataclasses import dataclass

_INT32 = range(-2**31, 2**31)
_UINT32 = range(2**32)


class Phase(enum.Enum):
    """The life of a non-blocking command (CommandEvent.Phase)."""
    STARTED = 1
    TAG_REACHED = 2
    PAUSED = 3
    RESUMED = 4
    DONE = 5
    FAILED = 6
    ABORTED = 7


class Severity(enum.Enum):
    """How serious an alarm is (AlarmSeverity)."""
    INFO = 1
    WARNING = 2
    ERROR = 3
    CRITICAL = 4


@dataclass(frozen=True, slots=True)
class CommandEvent:
    """A phase of a non-blocking command; `command` is the RPC name, e.g. "MoveAbsolute"."""
    command_id: str
    command: str
    phase: Phase
    point_name: str = ""      # point or path the command moves to
    tag_name: str = ""        # for Phase.TAG_REACHED
    tag_index: int = 0        # int32, for Phase.TAG_REACHED
    message: str = ""         # why, for Phase.FAILED

    def __post_init__(self):
        _check(isinstance(self.phase, Phase), "phase must be a Phase")
        _check(self.tag_index in _INT32, "tag_index must fit an int32")


@dataclass(frozen=True, slots=True)
class Alarm:
    """Seed clientAlarm; `code` is a seed return code (negative) or a device alarm code."""
    severity: Severity
    code: int                 # int32
    message: str
    command_id: str = ""      # the command the alarm is about, if any

    def __post_init__(self):
        _check(isinstance(self.severity, Severity), "severity must be a Severity")
        _check(self.code in _INT32, "code must fit an int32")


@dataclass(frozen=True, slots=True)
class StateChange:
    """The device moved in the state diagram; states are DeviceState names."""
    from_state: str
    to_state: str
    reason: str = ""


@dataclass(frozen=True, slots=True)
class DigitalIOSignal:
    """A signalDigitalIO watch fired; `bits_on` is the unit's bits when it fired."""
    command_id: str
    type: str
    unit_id: int              # int32
    bit_string: int           # uint32, the watched bits
    bits_on: int              # uint32

    def __post_init__(self):
        _check(self.unit_id in _INT32, "unit_id must fit an int32")
        _check(self.bit_string in _UINT32 and self.bits_on in _UINT32,
               "bit_string and bits_on must fit a uint32")


@dataclass(frozen=True, slots=True)
class RsvpRequest:
    """Seed clientEventRSVP / clientAlarmRSVP: the device asks the lock holder and waits."""
    rsvp_id: str
    alarm: bool               # True for clientAlarmRSVP
    event_id: str             # the seed's eventID of the question
    data: tuple[str, ...]
    choices: tuple[str, ...]
    default_choice: str       # taken when no answer arrives within timeout_s
    timeout_s: float          # seconds the device waits

    def __post_init__(self):
        _check(0 <= self.timeout_s * 1000 < 2**31, "timeout_s must be 0 .. 2**31 ms")


@dataclass(frozen=True, slots=True)
class RsvpAnswer:
    """The answer to an RsvpRequest, or its default when `timed_out`."""
    rsvp_id: str
    choice: str
    data: tuple[str, ...] = ()
    timed_out: bool = False


@dataclass(frozen=True, slots=True)
class OperatorMessage:
    """A message for the operator, posted by the lock holder `source`."""
    text: str
    source: str


@dataclass(frozen=True, slots=True)
class AlarmAcknowledged:
    """The alarm published as event `alarm_sequence` was acknowledged: `by` whom (the
    caller's token name, or its address with tokens off), through which front end (`client`)
    and for whom (`on_behalf_of`), as the caller's identity headers say."""
    alarm_sequence: int
    by: str
    client: str = ""
    on_behalf_of: str = ""


@dataclass(frozen=True, slots=True)
class EventsLost:
    """Events first_sequence..last_sequence (inclusive) that this subscriber will not get."""
    first_sequence: int
    last_sequence: int


Detail = (CommandEvent | Alarm | StateChange | DigitalIOSignal | RsvpRequest | RsvpAnswer
          | OperatorMessage | AlarmAcknowledged | EventsLost)
# What the device publishes; EventsLost is made by the bus for one subscriber only.
_PUBLISHED = (CommandEvent, Alarm, StateChange, DigitalIOSignal, RsvpRequest, RsvpAnswer,
              OperatorMessage, AlarmAcknowledged)


@dataclass(frozen=True, slots=True)
class Event:
    """One event of the stream: the seed's (event_id, data) plus the typed detail.

    `sequence` counts from 1 per bus; `time` is when it was published, unix seconds.
    """
    sequence: int
    time: float
    event_id: str
    data: tuple[str, ...]
    detail: Detail


def _check(ok: bool, message: str) -> None:
    # Checked at publish time so a bad value fails in the caller, not in every subscriber.
    if not ok:
        raise ValueError(message)


# The seed's eventID for each phase of a command.
PHASE_EVENT_IDS = {
    Phase.STARTED: "command_started", Phase.TAG_REACHED: "tag_reached",
    Phase.PAUSED: "command_paused", Phase.RESUMED: "command_resumed",
    Phase.DONE: "command_done", Phase.FAILED: "command_failed",
    Phase.ABORTED: "command_aborted",
}
