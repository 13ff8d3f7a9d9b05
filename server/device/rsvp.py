"""RSVP: the device asks the lock holder a question and waits (seed 2.2, clientEventRSVP and
clientAlarmRSVP), with a timeout and a safe default. The question and its answer both go on
the event stream, so every client sees the exchange."""
from __future__ import annotations

import itertools
import threading
from dataclasses import dataclass

from landscape.server.events import alarms
from landscape.server.events.bus import EventBus, RsvpAnswer, RsvpRequest, Severity
from landscape.server.device.sessions import Session


@dataclass
class _Pending:
    session: Session
    request: RsvpRequest
    answered: threading.Event
    answer: RsvpAnswer | None = None


class RsvpBroker:
    def __init__(self, bus: EventBus):
        self.bus = bus
        self.timeout = 30.0   # s the device's questions wait for their answer
        self._pending: dict[str, _Pending] = {}
        self._lock = threading.Lock()
        self._ids = itertools.count(1)

    def ask(self, session: Session | None, event_id: str, data, choices, default: str,
            timeout_s: float, alarm: bool = False) -> RsvpAnswer:
        """Ask `session` and block until it answers, it ends, or `timeout_s` passes; the
        default answers when nobody does (also when there is no session to ask)."""
        if default not in choices:
            raise ValueError(f"default {default!r} is not among the choices {choices!r}")
        rsvp_id = f"rsvp-{next(self._ids)}"
        event = self.bus.rsvp_request(rsvp_id, event_id, data, choices, default, timeout_s, alarm)
        if session is not None:
            pending = _Pending(session, event.detail, threading.Event())
            with self._lock:
                self._pending[rsvp_id] = pending
            if session.outbox.put(event.detail):
                pending.answered.wait(timeout_s)   # also woken by abandon(): then no answer
            else:
                self.bus.alarm(Severity.WARNING, alarms.OVERFLOW,
                               f"session {session.id} has too many questions waiting; "
                               f"{rsvp_id} takes its default")
            with self._lock:
                self._pending.pop(rsvp_id, None)
            if pending.answer is not None:
                self.bus.rsvp_answer(rsvp_id, pending.answer.choice, pending.answer.data)
                return pending.answer
        self.bus.rsvp_answer(rsvp_id, default, tuple(data), timed_out=True)
        return RsvpAnswer(rsvp_id, default, tuple(data), timed_out=True)

    def answer(self, session: Session, rsvp_id: str, choice: str, data) -> bool:
        """Take an answer; False if no such question is waiting for this session or the choice
        is not one offered (the question then keeps waiting)."""
        with self._lock:
            pending = self._pending.get(rsvp_id)
            if pending is None or pending.session is not session \
                    or choice not in pending.request.choices:
                return False
            pending.answer = RsvpAnswer(rsvp_id, choice, tuple(data))
        pending.answered.set()
        return True

    def abandon(self, session: Session) -> None:
        """The session ended: its questions take their defaults now."""
        with self._lock:
            waiting = [p for p in self._pending.values() if p.session is session]
        for pending in waiting:
            pending.answered.set()
