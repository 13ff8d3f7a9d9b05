"""The device's safety actions and the thread that carries them out (DESIGN.md section 5).

`SafetyActions` are the device's reactions that keep the cell safe; `SafetyWorker` is the thread
that carries out the ones that wait.

The disconnect handler and the shutdown stop can take a second of braking and powering down.
They never run on a gRPC thread or the event loop, where they would hold up other clients'
calls and keep-alives, nor behind a command: they are handed to this one thread, which runs
them in the order they came. A stop itself reaches the controller at once (it is a message to
the cycle, sent without waiting for anything); only the waiting for the arm to come to rest
happens here.
"""
from __future__ import annotations

import logging
import queue
import threading
from typing import Callable

from landscape.robot.controller import EnableState, EstopState
from landscape.server.device import states
from landscape.server.device.motion_control import MotionControl
from landscape.server.device.power import Power
from landscape.server.device.rsvp import RsvpBroker
from landscape.server.device.sessions import Session
from landscape.server.device.state_machine import StateMachine
from landscape.server.device.states import State
from landscape.server.errors import ControllerFailure, EstopActive
from landscape.server.events import alarms
from landscape.server.events.bus import EventBus, Severity
from landscape.server.link.clock import CycleProcessError
from landscape.server.link.controller_link import ControllerLink

log = logging.getLogger(__name__)

ESTOP_RELEASED_QUESTION = "estop_released"   # RSVP to the lock holder: reset now?
RESET, STAY = "reset", "stay"


class SafetyWorker:
    """One thread running safety actions in the order they came."""

    def __init__(self, name: str = "safety"):
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._idle = threading.Event()
        self._idle.set()
        self._thread = threading.Thread(target=self._run, name=name, daemon=True)
        self._thread.start()

    def submit(self, action: Callable[[], None], what: str) -> None:
        self._idle.clear()
        self._jobs.put((action, what))

    def wait_idle(self, timeout: float) -> bool:
        """True once every action submitted so far has run (for shutdown and tests)."""
        return self._idle.wait(timeout)

    def close(self, timeout: float = 5.0) -> None:
        self._jobs.put(None)
        self._thread.join(timeout)

    def _run(self) -> None:
        while (job := self._jobs.get()) is not None:
            action, what = job
            try:
                action()
            except Exception:
                log.exception("safety action failed: %s", what)
            if self._jobs.empty():
                self._idle.set()
        self._idle.set()


class SafetyActions:
    """The device's reactions that keep the cell safe: the seed's disconnect handler (2.2),
    the e-stop and the controller's reports and events, the controller's loss, and the
    question after an e-stop is released. They act on the controller at once and leave the
    waiting to the SafetyWorker; they change the state only through the state machine.

    reset(): the device's Reset (after an e-stop is released, if the lock holder says so);
    on_health(serving): the server's health; report_handlers: the cycle's reports by "op"
    that the cell's parts take (the motions take the rest)."""

    def __init__(self, state: StateMachine, power: Power, motions: MotionControl,
                 link: ControllerLink, bus: EventBus, rsvp: RsvpBroker,
                 reset: Callable[[], State], on_health: Callable[[bool], None],
                 report_handlers: dict[str, Callable[[dict], None]]):
        self.state, self.power, self.motions, self.link = state, power, motions, link
        self.bus, self.rsvp = bus, rsvp
        self.worker = SafetyWorker()
        self._reset, self._on_health, self._report_handlers = reset, on_health, report_handlers

    def session_ended(self, session: Session, reason: str) -> None:
        """A session ended (any thread): its questions take their defaults; if it held the
        lock, the seed's disconnect handler (2.2) runs on the safety worker."""
        self.rsvp.abandon(session)
        if not self.state.lose_holder(session):
            return
        self.bus.alarm(Severity.WARNING, alarms.LOCK_HOLDER_LOST,
                       f"lock holder {session.client_name} disconnected ({reason}): stopping, "
                       f"powering down and releasing")
        self.motions.stop_now()   # reaches the cycle at once; the waiting is the worker's
        self.worker.submit(lambda: self._disconnect_handler(session, reason),
                           f"disconnect handler for {session.client_name}")

    def _disconnect_handler(self, session: Session, reason: str) -> None:
        state = self.state
        if state.state in states.ACTIVE or self.power.drives_may_be_on():
            try:
                self.power.power_down(f"lock holder {session.client_name} gone")
            except ControllerFailure as failure:   # in Error now, its alarm raised
                self.bus.alarm(Severity.ERROR, alarms.LOCK_HOLDER_LOST,
                               f"lock holder {session.client_name} gone: {failure}; lock "
                               f"released")
                return
        with state.atomic():
            if state.state is State.INACTIVE:
                state.transition({State.INACTIVE}, State.UNLOCKED,
                                 f"lock holder {session.client_name} gone: {reason}")
        self.bus.alarm(Severity.WARNING, alarms.LOCK_HOLDER_LOST,
                       f"lock holder {session.client_name} gone: motion stopped, drives off, "
                       f"lock released")

    def controller_lost(self, reason: str) -> None:
        """The link lost the controller (its process died or fell silent): Error, an alarm
        naming the cause, the running command failed, health NOT_SERVING. The lock stays with
        its holder, who resets (which restarts the controller) or releases."""
        self._on_health(False)
        self.state.enter_error(alarms.CONTROLLER_LOST, f"controller lost: {reason}")
        self.motions.fail_running(f"controller lost: {reason}")
        self.state.controller_gone()

    def controller_event(self, text: str) -> None:
        """The controller's event function (LLI 5.2.1): its errors fault an active device. It
        comes before the Executor's report of the same cycle, so the e-stop is asked for."""
        log.warning("controller: %s", text)
        if "outbox" in text:
            self.bus.alarm(Severity.ERROR, alarms.OVERFLOW, f"controller: {text}")
            return
        try:
            estop = self.link.proxy.state().estop is EstopState.ESTOP
        except (CycleProcessError, TimeoutError):
            return   # the controller is gone: the link reports that
        if estop:
            self.state.enter_error(alarms.ESTOP, "e-stop pressed: motion stopped, drives off")
        elif self.state.state in states.ACTIVE:
            self.power.fault(alarms.CONTROLLER, f"controller error: {text}")
        else:
            self.bus.alarm(Severity.WARNING, alarms.CONTROLLER, f"controller: {text}")

    def on_cycle_message(self, msg: dict) -> None:
        """The Executor's reports (cycle/executor.py), in order, on the link's dispatch
        thread."""
        if msg.get("op") != "controller":
            self._report_handlers.get(msg.get("op"), self.motions.on_report)(msg)
            return
        estop = bool(msg["estop"])
        was_estop = self.state.controller_reported(EnableState(msg["enable"]), estop)
        if estop and not was_estop:
            self.state.enter_error(alarms.ESTOP, "e-stop pressed: motion stopped, drives off")
        elif was_estop and not estop and (holder := self.state.holder) is not None:
            threading.Thread(target=self._offer_reset, args=(holder,), daemon=True,
                             name="rsvp-estop-released").start()

    def _offer_reset(self, holder: Session) -> None:
        """The e-stop was released: ask the lock holder whether to reset now (default: stay)."""
        answer = self.rsvp.ask(holder, ESTOP_RELEASED_QUESTION, ("e-stop released; reset now?",),
                               (RESET, STAY), STAY, self.rsvp.timeout, alarm=True)
        if answer.choice == RESET and self.state.holder is holder:
            try:
                self._reset()
            except EstopActive as refused:  # pressed again meanwhile
                self.bus.alarm(Severity.WARNING, alarms.ESTOP, str(refused))
