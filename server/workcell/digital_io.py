"""The cell's digital I/O (seed 4, the DIGITAL_IO IDL): set, get, list, and signal watches.

Units of up to 32 bits, each all inputs or all outputs, come from the controller's I/O map (the
cell file). What the seed leaves open, decided as a cell integrator would expect:
- `type` is "input" or "output" and must be the unit's direction; only outputs are set. Bits
  are the unit's bit field (bit i is the value 1 << i); a bit no signal is declared at, or one
  set and cleared at once, is refused and nothing changes. Outputs wired to the world act on
  it: the tool changer's lock couples the tool at the flange (the tool offset and the
  collision scene follow, as after GetTool) and opens only with the tool in its rack slot (a
  changer does not drop a tool). The description goes to the server's log with the change.
- signalDigitalIO watches bits of a unit in the cycle (inputs.py): polled every
  pollingCycleTime ms (0: every cycle), it fires once, at the first poll that finds all of the
  bits set (bits set already fire at once), then it is done; not fired within pollingTimeOut
  ms (0: no timeout) it fails, saying so. It answers CMD_STARTED_OK with a command id; firing
  delivers, per callback type, a digital_io event (CLIENT_EVENT), an alarm (CLIENT_ALARM), or
  an RSVP question to the lock holder (the _RSVP types; the one answer, "acknowledge", or its
  timeout, is published), then the command's done event. At most MAX_WATCHES wait at once. A
  controller restart (after it was lost) ends the waiting ones as failed.
"""
from __future__ import annotations

import itertools
import logging
import math
import threading
from dataclasses import dataclass

from landscape.robot.controller import IoUnit, Status
from landscape.server.device.motion_control import MotionControl
from landscape.server.device.rsvp import RsvpBroker
from landscape.server.device.state_machine import StateMachine
from landscape.server.errors import ControllerFailure, OutOfRange, ParamError, ResourceExhausted
from landscape.server.events import alarms
from landscape.server.events.bus import EventBus, Phase, Severity
from landscape.server.link.controller_link import ControllerLink
from landscape.server.workcell.tooling import Tooling


log = logging.getLogger(__name__)

MAX_WATCHES = 64
CALLBACKS = ("event", "alarm", "event_rsvp", "alarm_rsvp")
ACKNOWLEDGE = "acknowledge"


@dataclass
class Watch:
    command_id: str
    type: str
    unit: int
    bits: int
    callback: str


class DigitalIO:
    def __init__(self, link: ControllerLink, motions: MotionControl, state: StateMachine,
                 bus: EventBus, rsvp: RsvpBroker, tooling: Tooling):
        self.link, self.motions, self.state = link, motions, state
        self.bus, self.rsvp, self.tooling = bus, rsvp, tooling
        self.units: dict[int, IoUnit] = {}
        self.watches: dict[str, Watch] = {}
        self._ids = itertools.count(1)
        self._lock = threading.Lock()

    def controller_started(self) -> None:
        self.units = {u.id: u for u in self.link.proxy.io_map()}
        with self._lock:
            waiting, self.watches = list(self.watches.values()), {}
        for watch in waiting:
            self._finish(watch, Phase.FAILED, "the controller was restarted")

    # ---- seed 4.1 setDigitalIO, getDigitalIO ------------------------------------------------

    def set(self, type: str, unit_id: int, bits_on: int, bits_off: int, description: str) -> None:
        unit = self._unit(type, unit_id)
        if type != "output":
            raise ParamError(f"only outputs are set; unit {unit_id} ({unit.name}) holds inputs")
        if bits_on & bits_off:
            raise ParamError(f"bits {bits_on & bits_off:#x} are both set and cleared")
        self._declared(unit, bits_on | bits_off)
        changer = self.tooling.changer_bits(unit)
        if (bits_on | bits_off) & changer:
            self.tooling.check_changer(release=bool(bits_off & changer))
        log.info("setDigitalIO unit %d (%s): on %#x off %#x: %s", unit_id, unit.name, bits_on,
                 bits_off, description)
        if self.link.proxy.write_io_unit(unit_id, bits_on, bits_off) is not Status.OK:
            raise ControllerFailure(f"the controller refused to write unit {unit_id}")
        if (bits_on | bits_off) & changer:
            self.tooling.follow_changer()

    def get(self, type: str, unit_id: int) -> int:
        self._unit(type, unit_id)
        return self.link.proxy.read_io_unit(unit_id)

    # ---- seed 4.1 signalDigitalIO -----------------------------------------------------------

    def signal(self, type: str, unit_id: int, bits: int, timeout_ms: int, period_ms: int,
               callback: str) -> str:
        unit = self._unit(type, unit_id)
        if bits == 0:
            raise ParamError("bit_string names no bit to watch")
        self._declared(unit, bits)
        if timeout_ms < 0 or period_ms < 0:
            raise OutOfRange("polling_timeout and polling_cycle_time are 0 or more ms")
        if callback not in CALLBACKS:
            raise ParamError(f"callback type must be one of {', '.join(CALLBACKS)}")
        cycle_ms = self.link.cycle_time * 1000.0
        watch = Watch(f"SignalDigitalIO-{next(self._ids)}", type, unit_id, bits, callback)
        with self._lock:
            if len(self.watches) >= MAX_WATCHES:
                raise ResourceExhausted(f"{MAX_WATCHES} signalDigitalIO watches are waiting, "
                                        f"the most this device keeps")
            self.watches[watch.command_id] = watch
        self.bus.command(watch.command_id, "SignalDigitalIO", Phase.STARTED,
                                self._where(watch))
        try:
            self.motions.send({
                "op": "watch", "id": watch.command_id, "unit": unit_id, "bits": bits,
                "period": max(1, math.ceil(period_ms / cycle_ms - 1e-9)),
                "timeout": math.ceil(timeout_ms / cycle_ms - 1e-9)})
        except ControllerFailure:
            with self._lock:
                self.watches.pop(watch.command_id, None)
            raise
        return watch.command_id

    def on_report(self, msg: dict) -> None:
        """The cycle's "io_signal" and "io_timeout" reports (inputs.py)."""
        with self._lock:
            watch = self.watches.pop(msg["id"], None)
        if watch is None:
            return
        bits, cycle = int(msg["bits"]), int(msg["sequence"])
        if msg["op"] == "io_timeout":
            self._finish(watch, Phase.FAILED, f"timeout: bits {watch.bits:#x} were not all set "
                                              f"by cycle {cycle} (they read {bits:#x})")
            return
        what = (f"bits {watch.bits:#x} of {self._where(watch)} set in cycle {cycle} (the unit "
                f"reads {bits:#x})")
        if watch.callback == "event":
            self.bus.digital_io(watch.command_id, watch.type, watch.unit, watch.bits, bits)
            self._finish(watch, Phase.DONE, what)
        elif watch.callback == "alarm":
            self.bus.alarm(Severity.WARNING, alarms.DIGITAL_IO, what, watch.command_id)
            self._finish(watch, Phase.DONE, what)
        else:   # RSVP: the question waits for its answer on a thread of its own
            threading.Thread(target=self._ask, args=(watch, what, bits), daemon=True,
                             name=f"rsvp-{watch.command_id}").start()

    def _ask(self, watch: Watch, what: str, bits: int) -> None:
        answer = self.rsvp.ask(self.state.holder, "digital_io",
                                 (watch.command_id, watch.type, str(watch.unit),
                                  str(watch.bits), str(bits)),
                                 (ACKNOWLEDGE,), ACKNOWLEDGE, self.rsvp.timeout,
                                 alarm=watch.callback == "alarm_rsvp")
        self._finish(watch, Phase.DONE, f"{what}; {'no answer' if answer.timed_out else 'answered'}"
                                        f" {answer.choice}")

    def _finish(self, watch: Watch, phase: Phase, message: str) -> None:
        self.bus.command(watch.command_id, "SignalDigitalIO", phase, self._where(watch),
                                message=message)

    # ---- checks -----------------------------------------------------------------------------

    @staticmethod
    def _where(watch: Watch) -> str:
        return f"{watch.type} unit {watch.unit}"

    def _unit(self, type: str, unit_id: int) -> IoUnit:
        if type not in ("input", "output"):
            raise ParamError(f"type must be \"input\" or \"output\", got {type!r}")
        unit = self.units.get(unit_id)
        if unit is None:
            raise ParamError(f"no I/O unit {unit_id} (units: "
                             f"{', '.join(f'{u.id} {u.name}' for u in self.units.values())})")
        if unit.direction != type:
            raise ParamError(f"unit {unit_id} ({unit.name}) holds {unit.direction}s, not "
                             f"{type}s")
        return unit

    @staticmethod
    def _declared(unit: IoUnit, bits: int) -> None:
        stray = bits & ~unit.mask
        if stray or bits < 0:
            raise OutOfRange(f"unit {unit.id} ({unit.name}) has no signal at bits {stray:#x} "
                             f"(declared: {unit.mask:#x})")
