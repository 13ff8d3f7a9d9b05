"""The thread that carries out the device's safety actions (DESIGN.md section 5).

The disconnect handler and the shutdown stop can take a second of braking and powering down.
They never run on a gRPC thread or the event loop, where they would hold up other clients'
calls and keep-alives, nor behind a command: they are handed to this one thread, which runs
them in the order they came. A stop itself reaches the controller at once (it is a message to
the cycle, sent without waiting for anything); only the waiting for the arm to come to rest
happens here.
"""
from __future__ import annotations

import contextlib
import logging
import queue
import threading
from typing import Callable

from landscape.server.events import alarms
from landscape.server.device import states
from landscape.server.errors import ControllerFailure, EstopActive
from landscape.server.events.bus import Severity
from landscape.server.device.sessions import Session
from landscape.server.device.states import State
from landscape.server.link.clock import CycleProcessError
from landscape.robot.controller import EnableState, EstopState

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
    """The device's reactions that keep the cell safe, mixed into Device (device.py): the
    seed's disconnect handler (2.2), faults into Error, the e-stop and the controller's reports
    and events, the controller's loss, and the question after an e-stop is released. They act
    on the controller at once and leave the waiting to the SafetyWorker."""

    def _session_ended(self, session: Session, reason: str) -> None:
        """A session ended (any thread): its questions take their defaults; if it held the
        lock, the seed's disconnect handler (2.2) runs on the safety worker."""
        self.rsvp.abandon(session)
        with self._state_lock:
            if self._holder is not session:
                return
            self._holder = self._lease = None
            self._epoch += 1
            self.manual_control = "off"
        self.bus.alarm(Severity.WARNING, alarms.LOCK_HOLDER_LOST,
                       f"lock holder {session.client_name} disconnected ({reason}): stopping, "
                       f"powering down and releasing")
        self.motions.stop_now()   # reaches the cycle at once; the waiting is the worker's
        self.safety.submit(lambda: self._disconnect_handler(session, reason),
                           f"disconnect handler for {session.client_name}")

    def _disconnect_handler(self, session: Session, reason: str) -> None:
        if self._state in states.ACTIVE or self._drives_may_be_on():
            try:
                self._power_down(f"lock holder {session.client_name} gone")
            except ControllerFailure as failure:   # in Error now, its alarm raised
                self.bus.alarm(Severity.ERROR, alarms.LOCK_HOLDER_LOST,
                               f"lock holder {session.client_name} gone: {failure}; lock "
                               f"released")
                return
        with self._state_lock:
            if self._state is State.INACTIVE:
                self._transition({State.INACTIVE}, State.UNLOCKED,
                                 f"lock holder {session.client_name} gone: {reason}")
        self.bus.alarm(Severity.WARNING, alarms.LOCK_HOLDER_LOST,
                       f"lock holder {session.client_name} gone: motion stopped, drives off, "
                       f"lock released")

    def _drives_may_be_on(self) -> bool:
        """The drives are on, or coming on (an Activate that was under way), as far as the
        controller says (or last reported, if it cannot say)."""
        try:
            power = self.controller.state().enable
        except (CycleProcessError, TimeoutError):
            power = self._power
        return power is not EnableState.DISABLED

    def _fault(self, code: int, message: str) -> bool:
        """Into Error (from any state but Idle) with an alarm; True if it entered it now. In
        Error already, a new cause (the controller lost during an e-stop) still raises its
        alarm and becomes the error; the same cause again (an e-stop seen by both the
        controller's event and its report) is said once."""
        with self._state_lock:
            if self._state is State.IDLE:
                return False
            entered = self._state is not State.ERROR
            if not entered and message == self._error:
                return False
            self._error = message
            if entered:
                self._transition(set(State), State.ERROR, message)
        self.bus.alarm(Severity.CRITICAL if code in (alarms.ESTOP, alarms.CONTROLLER_LOST)
                       else Severity.ERROR, code, message)
        return entered

    def fault(self, code: int, message: str) -> None:
        """Into Error with an alarm and the drives off (a fault found above the controller,
        such as a compliance panic that asks for it)."""
        if self._fault(code, message):
            with contextlib.suppress(ControllerFailure):
                self._command_controller("disable")

    def controller_lost(self, reason: str) -> None:
        """The link lost the controller (its process died or fell silent): Error, an alarm
        naming the cause, the running command failed, health NOT_SERVING. The lock stays with
        its holder, who resets (which restarts the controller) or releases."""
        self.on_health(False)
        self._fault(alarms.CONTROLLER_LOST, f"controller lost: {reason}")
        self.motions.fail_running(f"controller lost: {reason}")
        with self._controller_changed:
            self._controller_changed.notify_all()

    def _controller_event(self, text: str) -> None:
        """The controller's event function (LLI 5.2.1): its errors fault an active device. It
        comes before the Executor's report of the same cycle, so the e-stop is asked for."""
        log.warning("controller: %s", text)
        if "outbox" in text:
            self.bus.alarm(Severity.ERROR, alarms.OVERFLOW, f"controller: {text}")
            return
        try:
            estop = self.controller.state().estop is EstopState.ESTOP
        except (CycleProcessError, TimeoutError):
            return   # the controller is gone: the link reports that
        if estop:
            self._fault(alarms.ESTOP, "e-stop pressed: motion stopped, drives off")
        elif self._state in states.ACTIVE:
            self.fault(alarms.CONTROLLER, f"controller error: {text}")
        else:
            self.bus.alarm(Severity.WARNING, alarms.CONTROLLER, f"controller: {text}")

    def on_cycle_message(self, msg: dict) -> None:
        """The Executor's reports (executor.py), in order, on the link's dispatch thread."""
        if msg.get("op") != "controller":
            self.report_handlers.get(msg.get("op"), self.motions.on_report)(msg)
            return
        estop, was_estop = bool(msg["estop"]), self._estop
        with self._controller_changed:
            self._power, self._estop = EnableState(msg["enable"]), estop
            self._controller_changed.notify_all()
        if estop and not was_estop:
            self._fault(alarms.ESTOP, "e-stop pressed: motion stopped, drives off")
        elif was_estop and not estop and self._holder is not None:
            holder = self._holder
            threading.Thread(target=self._offer_reset, args=(holder,), daemon=True,
                             name="rsvp-estop-released").start()

    def _offer_reset(self, holder: Session) -> None:
        """The e-stop was released: ask the lock holder whether to reset now (default: stay)."""
        answer = self.rsvp.ask(holder, ESTOP_RELEASED_QUESTION, ("e-stop released; reset now?",),
                               (RESET, STAY), STAY, self.rsvp_timeout, alarm=True)
        if answer.choice == RESET and self._holder is holder:
            try:
                self.reset()
            except EstopActive as refused:  # pressed again meanwhile
                self.bus.alarm(Severity.WARNING, alarms.ESTOP, str(refused))

