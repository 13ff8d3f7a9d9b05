"""The device's state machine (DESIGN.md section 4): the one owner of the state, the lock holder
and its lease, the epoch, the power and e-stop as the controller last reported them, the error
and the manual-control mode, and of every change to them.

Every change of state is a compare-and-set against the states it may come from (`transition`),
made under one short lock with its event published before the lock is let go, so the events
come in the order of the changes and no change overwrites another. A caller that must read
and change together (a motion registered and started, say) does it inside `atomic()`; nothing
that may wait (a file, the controller) happens there.

Admission: `admit` refuses a call the state table (states.py) or the lease does not allow, and
`command` runs a body once its turn has come: mutating commands one at a time, the immediate
ones (they stop the arm) without waiting for that turn. A lock that changes hands bumps the
epoch; a command admitted under an older one cannot act (`check_epoch`), because the
disconnect handler may have run while it was being prepared.
"""
from __future__ import annotations

import contextlib
import logging
import secrets
import threading
from typing import Callable

from landscape.robot.controller import EnableState
from landscape.server.device import states
from landscape.server.device.sessions import Session
from landscape.server.device.states import Lease, State
from landscape.server.errors import NotLockHolder, ParamError, WrongState
from landscape.server.events import alarms
from landscape.server.events.bus import EventBus, Severity

log = logging.getLogger(__name__)

MANUAL_OFF = "off"   # seed 3.7.3: otherwise "teachpendant" or "spaceball"


class _Atomic:
    """StateMachine.atomic's block: the machine's re-entrant lock, entered as the machine. One
    object for every use (it keeps no state of a use): a status read takes it on every call,
    and a generator's context manager cost it several microseconds."""

    __slots__ = ("_lock", "_machine")

    def __init__(self, lock: threading.RLock, machine: StateMachine):
        self._lock, self._machine = lock, machine

    def __enter__(self) -> StateMachine:
        self._lock.acquire()
        return self._machine

    def __exit__(self, *exc) -> None:
        self._lock.release()


class StateMachine:
    def __init__(self, bus: EventBus):
        self._bus = bus
        self._state = State.IDLE
        self._holder: Session | None = None
        self._lease: str | None = None
        self._epoch = 0                    # +1 whenever the lock changes hands
        self._local = threading.local()    # the epoch a command was admitted under
        self._error = ""
        self._power = EnableState.DISABLED   # the controller's last reported power state
        self._estop = False
        self._manual = MANUAL_OFF
        self._lock = threading.RLock()
        self._atomic = _Atomic(self._lock, self)
        self.turn = threading.Lock()   # the mutating commands', one at a time
        self._controller_changed = threading.Condition()

    # ---- what it holds -----------------------------------------------------------------------

    @property
    def state(self) -> State:
        return self._state

    @property
    def holder(self) -> Session | None:
        return self._holder

    @property
    def epoch(self) -> int:
        return self._epoch

    @property
    def error(self) -> str:
        return self._error

    @property
    def power(self) -> EnableState:
        return self._power

    @property
    def estop(self) -> bool:
        return self._estop

    @property
    def manual_control(self) -> str:
        return self._manual

    def set_manual_control(self, mode: str) -> None:
        self._manual = mode

    def set_error(self, message: str) -> None:
        self._error = message

    def atomic(self) -> _Atomic:
        """A block of reads and transitions that no other change interleaves with (re-entrant;
        nothing inside may wait)."""
        return self._atomic

    # ---- transitions -------------------------------------------------------------------------

    def transition(self, expected, new: State, reason: str) -> State:
        """Compare-and-set: move to `new` if the state is one of `expected` (else WrongState);
        returns the state it left. The event is published before the lock is let go."""
        with self._lock:
            old = self._state
            if old not in expected:
                raise WrongState(f"cannot go {old.value} -> {new.value} ({reason}): the state "
                                 f"changed meanwhile", state=old.value)
            self._state = new
            if old is not new:
                log.info("%s -> %s: %s", old.value, new.value, reason)
                self._bus.state_change(old.value, new.value, reason)
            return old

    def initialised(self) -> None:
        """The controller is up: Unlocked, or Error if its e-stop is pressed."""
        estop = self._estop
        self.transition({State.IDLE}, State.ERROR if estop else State.UNLOCKED,
                        "e-stop pressed at start-up" if estop else "controller initialised")
        if estop:
            self._error = "e-stop pressed"

    def enter_error(self, code: int, message: str) -> bool:
        """Into Error (from any state but Idle) with an alarm; True if it entered it now. In
        Error already, a new cause (the controller lost during an e-stop) still raises its
        alarm and becomes the error; the same cause again (an e-stop seen by both the
        controller's event and its report) is said once."""
        with self._lock:
            if self._state is State.IDLE:
                return False
            entered = self._state is not State.ERROR
            if not entered and message == self._error:
                return False
            self._error = message
            if entered:
                self.transition(set(State), State.ERROR, message)
        self._bus.alarm(Severity.CRITICAL if code in (alarms.ESTOP, alarms.CONTROLLER_LOST)
                        else Severity.ERROR, code, message)
        return entered

    def leave_error(self) -> State:
        """Reset: Error -> Inactive (the lock held) or Unlocked, the error cleared; the state
        it is in now."""
        with self._lock:
            if self._state is not State.ERROR:
                return self._state
            target = State.INACTIVE if self._holder else State.UNLOCKED
            self.transition({State.ERROR}, target, "reset")
            self._error = ""
            return target

    # ---- the lock ----------------------------------------------------------------------------

    def take_lock(self, session: Session) -> str:
        """Unlocked -> Inactive, held by `session`; its new lease."""
        with self._lock:
            if session.ended.is_set():  # ended since it was looked up: its handler ran already
                raise ParamError(f"session {session.id!r} has ended")
            self.transition({State.UNLOCKED}, State.INACTIVE, f"locked by {session.client_name}")
            self._holder, self._lease = session, secrets.token_urlsafe(24)
            self._epoch += 1
            return self._lease

    def release_lock(self) -> None:
        """Inactive -> Unlocked (in Error it stays there, unlocked, until Reset); manual
        control ends with the lock."""
        with self._lock:
            holder = self._holder
            if self._state is State.INACTIVE:
                self.transition({State.INACTIVE}, State.UNLOCKED,
                                f"released by {holder.client_name}")
            self._drop_holder()

    def lose_holder(self, session: Session) -> bool:
        """`session` ended: if it held the lock, nobody does now (the state is the disconnect
        handler's to change); True if it did."""
        with self._lock:
            if self._holder is not session:
                return False
            self._drop_holder()
            return True

    def _drop_holder(self) -> None:
        self._holder = self._lease = None
        self._epoch += 1
        self._manual = MANUAL_OFF

    # ---- admission ---------------------------------------------------------------------------

    def admit(self, rpc: str, lease: str | None) -> None:
        """Refuse `rpc` now if the state or the caller does not allow it (changes nothing)."""
        rule = states.RULES[rpc]
        with self._lock:
            self._check_state(rpc, rule)
            self._check_lease(rpc, rule, lease)

    @contextlib.contextmanager
    def command(self, rpc: str, lease: str | None):
        """Run the body of `rpc` if the state table allows it now, for this caller.

        Read-only RPCs run at once; immediate ones (they stop the arm) without waiting for
        other commands; the other mutating ones one at a time. The state and the lease are
        checked once the turn has come, so a refused call changes nothing.
        """
        rule = states.RULES[rpc]
        if rule.lease is Lease.NONE:
            self._check_state(rpc, rule)
            yield
            return
        with contextlib.nullcontext() if rule.immediate else self.turn:
            with self._admitted(rpc, rule, lease):
                yield

    @contextlib.contextmanager
    def command_if_free(self, rpc: str, lease: str | None):
        """`command` for a mutating body that never waits, if no other command holds the
        turn now: yields True (the body runs, holding the turn), else False at once (nothing
        checked: the caller takes its turn where waiting is allowed)."""
        if not self.turn.acquire(blocking=False):
            yield False
            return
        try:
            with self._admitted(rpc, states.RULES[rpc], lease):
                yield True
        finally:
            self.turn.release()

    @contextlib.contextmanager
    def _admitted(self, rpc: str, rule: states.Rule, lease: str | None):
        with self._lock:
            self._check_state(rpc, rule)
            self._check_lease(rpc, rule, lease)
            self._local.epoch = self._epoch
        try:
            yield
        finally:
            self._local.epoch = None

    def check_holder(self, what: str, lease: str | None) -> None:
        """For a read-only RPC's parts that change something (vendor commands): the lock
        holder's lease while the device is locked, anyone's call when it is not."""
        with self._lock:
            self._check_lease(what, states.Rule(states.ALL, Lease.HOLDER_IF_LOCKED, "-"), lease)

    def check_epoch(self) -> None:
        """Called inside `atomic()` before a command acts: the lock must not have changed
        hands since it was admitted."""
        epoch = getattr(self._local, "epoch", None)
        if epoch is not None and epoch != self._epoch:
            raise NotLockHolder("the lock changed hands while the command was being prepared")

    def _check_state(self, rpc: str, rule: states.Rule) -> None:
        if self._state not in rule.states:
            if rpc == "Lock" and self._holder is not None:
                raise WrongState(f"the device is locked by {self._holder.client_name}",
                                 state=self._state.value, holder=self._holder.client_name)
            valid = ", ".join(sorted(s.value for s in rule.states))
            raise WrongState(f"{rpc} is not valid in state {self._state.value} (seed {rule.seed}: "
                             f"valid in {valid})", state=self._state.value)

    def _check_lease(self, rpc: str, rule: states.Rule, lease: str | None) -> None:
        if rule.lease in (Lease.SESSION, Lease.NONE):
            return
        if rule.lease is Lease.HOLDER_IF_LOCKED and self._holder is None:
            return
        if self._lease is None or not lease or not secrets.compare_digest(lease, self._lease):
            holder = self._holder.client_name if self._holder else "nobody"
            raise NotLockHolder(f"{rpc} needs the lock holder's lease (locked by {holder})")

    # ---- the controller's power and e-stop, as it reports them -------------------------------

    def controller_reported(self, power: EnableState, estop: bool) -> bool:
        """The controller's latest power state and e-stop; wakes whoever waits on them.
        Returns whether the e-stop was pressed before."""
        with self._controller_changed:
            was_estop = self._estop
            self._power, self._estop = power, estop
            self._controller_changed.notify_all()
        return was_estop

    def controller_gone(self) -> None:
        """Wake whoever waits on the controller: it will not report again."""
        with self._controller_changed:
            self._controller_changed.notify_all()

    def wait_controller(self, done: Callable[[], bool], timeout: float) -> bool:
        """Until done() (checked at every report of the controller), at most `timeout` s."""
        with self._controller_changed:
            return self._controller_changed.wait_for(done, timeout)
