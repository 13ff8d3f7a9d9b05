"""Acknowledged alarms: the device's record of who acknowledged which alarm, so that every
client sees the same acknowledgements (an AlarmAcknowledged event each), not one front end's
memory of its own people's.

An alarm is acknowledged once: a second acknowledgement changes nothing and is answered with
the first. Only an alarm the bus still keeps can be acknowledged (its history: DEFAULT_HISTORY
events); the acknowledgements kept are bounded the same way.
"""
from __future__ import annotations

import threading
from collections import OrderedDict

from landscape.server.errors import NotFound
from landscape.server.events.bus import Alarm, Event, EventBus


class Acknowledgements:
    def __init__(self, bus: EventBus):
        self._bus = bus
        self._lock = threading.Lock()   # one acknowledgement at a time: none is made twice
        self._made: OrderedDict[int, Event] = OrderedDict()   # alarm sequence -> its event

    def acknowledge(self, sequence: int, by: str, client: str = "",
                    on_behalf_of: str = "") -> tuple[Event, bool]:
        """The AlarmAcknowledged event of the alarm numbered `sequence`, and whether this call
        made it (False: it was acknowledged before, by the event's `by`). NotFound if
        `sequence` is not an alarm the bus keeps."""
        with self._lock:
            made = self._made.get(sequence)
            if made is not None:
                return made, False
            alarm = self._bus.kept(sequence)
            if alarm is None or not isinstance(alarm.detail, Alarm):
                what = ("no longer kept, or not yet published" if alarm is None
                        else f"a {alarm.event_id} event, not an alarm")
                raise NotFound(f"event {sequence} is {what}: nothing to acknowledge",
                               field="sequence")
            event = self._bus.alarm_acknowledged(sequence, by, client, on_behalf_of)
            self._made[sequence] = event
            while len(self._made) > max(self._bus.history_size, 1):
                self._made.popitem(last=False)
            return event, True
