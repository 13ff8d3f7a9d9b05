"""The device: one robot's state machine, lock, power and safety, above its controller.

Every transport (gRPC servicers now; the CRCL gateway and the dashboard through gRPC) reaches
the robot through these methods and `motions` (motion_control.py). They take and return domain
values in SI (convert.py does the units); they raise CommandError subclasses (errors.py) and
change nothing when they do.

Concurrency:
- Every state change is a compare-and-set against the states it may come from
  (`_transition`, under the short `_state_lock`), and its event is published under the same
  lock, so the events come in the order of the changes and no change overwrites another.
  Nothing that may wait (a file, the controller) happens under that lock: settings are
  stored under a lock of their own.
- Mutating commands run one at a time under `_command_lock` (`command()`); the state and the
  lease are checked (again) once it is held. Commands that stop the arm (`immediate`:
  StopMotion, AbortMotion, Deactivate) do not wait for that lock.
- A lock that changes hands bumps `_epoch`; a command admitted under an older epoch cannot
  start a motion (the disconnect handler may run while it plans).
- Safety actions (lock holder gone, e-stop, controller lost) do not wait for any command: the
  controller is told at once, the waiting happens on the safety worker (safety.py).
"""
from __future__ import annotations

import contextlib
import logging
import secrets
import threading
from dataclasses import dataclass
from typing import Callable


from landscape.server.events import alarms
from landscape.server.device import states, stored_settings
from landscape.server.planning.collision import CollisionScene
from landscape.server.errors import (CommandError, ControllerFailure, EstopActive, NotLockHolder,
                                     ParamError, WrongState)
from landscape.server.events.bus import EventBus, Severity
from landscape.server.cycle.feedback import Sample
from landscape.server.device.motion_control import MotionControl
from landscape.server.planning.paths import PathStore
from landscape.server.device.rsvp import RsvpBroker
from landscape.server.device.safety import SafetyActions, SafetyWorker
from landscape.server.device.sessions import Session, SessionRegistry
from landscape.server.device.motion_settings import MotionSettings
from landscape.server.device.states import Lease, State
from landscape.sim import panel
from landscape.robot.arm import ArmModel
from landscape.robot.controller import EnableState, InitState, Status
from landscape.server.link.clock import CycleProcessError
from landscape.robot.kinematics import Kinematics

log = logging.getLogger(__name__)

# A safety stop brakes at the arm's full deceleration: the TX90 at full speed stops within
# max velocity / max acceleration = 1/3 s (main axes) and 1/5 s (wrist), then settles.
SAFETY_STOP_TIMEOUT = 2.0


@dataclass(frozen=True)
class DeviceStatus:
    state: State
    locked: bool
    lock_holder: str
    error: str
    estop: bool
    manual_control: str
    command_id: str


class Device(SafetyActions):
    def __init__(self, link, bus: EventBus, arm: ArmModel, *, collisions: CollisionScene,
                 paths: PathStore | None = None,
                 outputs: set[str] = frozenset(), enable_timeout: float = 5.0,
                 keepalive_interval: float = 0.5, keepalive_timeout: float = 2.0,
                 reset_settings: bool = False):
        self.link = link
        self.bus = bus
        self.arm = arm
        self.kinematics = Kinematics(arm)
        # What is where in the cell, for checking motions before they start (collision/).
        self.collisions = collisions
        self.enable_timeout = enable_timeout
        self.rsvp_timeout = 30.0
        self.rsvp = RsvpBroker(bus)
        self.safety = SafetyWorker()
        self.sessions = SessionRegistry(self._session_ended, keepalive_interval, keepalive_timeout)
        self.on_health: Callable[[bool], None] = lambda serving: None
        self._state = State.IDLE
        self._holder: Session | None = None
        self._lease: str | None = None
        self._epoch = 0                    # +1 whenever the lock changes hands
        self._local = threading.local()    # the epoch a command was admitted under
        self._store = paths or PathStore()
        defaults = MotionSettings(arm)
        self._settings = (defaults if reset_settings
                          else stored_settings.from_record(defaults, self._store.load_settings()))
        if reset_settings:
            with contextlib.suppress(CommandError):   # reported by the store; in force anyway
                self._store.save_settings(stored_settings.to_record(defaults))
        self._error = ""
        self._power = EnableState.DISABLED   # the controller's last reported power state
        self._estop = False
        self._controller_changed = threading.Condition()
        self._state_lock = threading.RLock()
        self._settings_lock = threading.Lock()   # one settings change at a time
        self._command_lock = threading.Lock()
        self.motions = MotionControl(self, self._store, set(outputs))
        self.manual_control = "off"        # seed 3.7.3: "teachpendant", "spaceball" or "off"
        # The cell's other parts (app.py wires them): reports from the cycle by "op", and
        # what to do each time the controller has (re)started.
        self.report_handlers: dict[str, Callable[[dict], None]] = {}
        self.on_controller_start: list[Callable[[], None]] = []

    @property
    def controller(self):
        return self.link.proxy

    # ---- life cycle ------------------------------------------------------------------------

    def start(self, timeout: float = 30.0) -> None:
        """Initialise and home the controller (LLI_init); Idle until then, Unlocked after."""
        self._start_controller(timeout)
        self._transition({State.IDLE}, State.ERROR if self._estop else State.UNLOCKED,
                         "e-stop pressed at start-up" if self._estop else "controller initialised")
        if self._estop:
            self._error = "e-stop pressed"

    def _start_controller(self, timeout: float, after: int = -1) -> None:
        """Initialise the controller and wait for its first cycle's feedback (a row after
        cycle `after`: the ring outlives a controller); power and e-stop are then its own."""
        self.controller.plug_event_func(self._controller_event)
        if self.controller.state().init is not InitState.INITIALIZED:
            if self.controller.init() is not Status.OK:
                raise ControllerFailure("the controller did not initialise")
        if not self._wait_controller(lambda: self.link.feedback.head > after, timeout):
            raise ControllerFailure("no feedback from the controller")
        sample = self.link.feedback.latest()
        with self._controller_changed:
            self._power, self._estop = sample.enable, sample.estop
        for started in self.on_controller_start:
            started()

    def close(self, timeout: float = 5.0) -> None:
        """Leave the arm safe: the lock holder's session ends (the disconnect handler stops,
        deactivates and releases), then nothing more is accepted."""
        self.sessions.close()
        self.safety.wait_idle(timeout)
        self.safety.close()
        self.motions.close()

    # ---- state -----------------------------------------------------------------------------

    @property
    def state(self) -> State:
        return self._state

    @property
    def lock_holder(self) -> Session | None:
        return self._holder

    @property
    def settings(self) -> MotionSettings:
        return self._settings

    @property
    def error(self) -> str:
        return self._error

    def status(self) -> DeviceStatus:
        with self._state_lock:
            return DeviceStatus(self._state, self._holder is not None,
                                self._holder.client_name if self._holder else "", self._error,
                                self._estop, self.manual_control, self.motions.running_id)

    def _transition(self, expected, new: State, reason: str) -> State:
        """Compare-and-set: move to `new` if the state is one of `expected` (else WrongState);
        returns the state it left. The event is published before the lock is let go."""
        with self._state_lock:
            old = self._state
            if old not in expected:
                raise WrongState(f"cannot go {old.value} -> {new.value} ({reason}): the state "
                                 f"changed meanwhile", state=old.value)
            self._state = new
            if old is not new:
                log.info("%s -> %s: %s", old.value, new.value, reason)
                self.bus.state_change(old.value, new.value, reason)
            return old

    def admit(self, rpc: str, lease: str | None) -> None:
        """Refuse `rpc` now if the state or the caller does not allow it (changes nothing)."""
        rule = states.RULES[rpc]
        with self._state_lock:
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
        with contextlib.nullcontext() if rule.immediate else self._command_lock:
            with self._state_lock:
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
        with self._state_lock:
            self._check_lease(what, states.Rule(states.ALL, Lease.HOLDER_IF_LOCKED, "-"), lease)

    def check_epoch(self) -> None:
        """Called with `_state_lock` held before a command acts: the lock must not have
        changed hands since it was admitted."""
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

    # ---- 3.1 lock, release, activate, deactivate --------------------------------------------

    def lock(self, session_id: str, secret: str) -> str:
        session = self.sessions.owned(session_id, secret)
        if session is None:
            raise ParamError(f"no open session {session_id!r} with that secret: open one with "
                             f"SessionService.Connect and pass its session_id and session_secret")
        with self._state_lock:
            if session.ended.is_set():  # ended since we looked it up: its handler ran already
                raise ParamError(f"session {session_id!r} has ended")
            self._transition({State.UNLOCKED}, State.INACTIVE, f"locked by {session.client_name}")
            self._holder, self._lease = session, secrets.token_urlsafe(24)
            self._epoch += 1
            return self._lease

    def release(self) -> None:
        with self._state_lock:
            holder = self._holder
            if self._state is State.INACTIVE:  # in Error it stays there, unlocked, until Reset
                self._transition({State.INACTIVE}, State.UNLOCKED,
                                 f"released by {holder.client_name}")
            self._holder = self._lease = None
            self._epoch += 1
            self.manual_control = "off"

    def activate(self) -> None:
        """Drives on, then Resting; if anything fails on the way (the e-stop, the controller,
        the lock holder leaving meanwhile), the drives are turned off again."""
        epoch = self._epoch
        try:
            self._command_controller("enable")
            self._wait_controller(lambda: self._power is EnableState.ENABLED or self._estop
                                  or self.link.lost is not None or self._epoch != epoch,
                                  self.enable_timeout)
            with self._state_lock:
                self.check_epoch()
                if self._power is not EnableState.ENABLED:
                    why = self._error or ("e-stop pressed" if self._estop else "timed out")
                    raise ControllerFailure(f"the drives did not come on ({why})")
                self._transition({State.INACTIVE}, State.RESTING, "activated")
        except BaseException:
            with contextlib.suppress(Exception):
                self.controller.disable()
            raise

    def deactivate(self) -> None:
        """Stop along the path (at the arm's full deceleration) if moving, then drives off."""
        self._power_down("deactivated")

    def _power_down(self, reason: str, timeout: float = SAFETY_STOP_TIMEOUT) -> None:
        """Stop any motion (no new one can start meanwhile), disable, wait, then Inactive.
        Drives that do not go off are a fault: Error and ControllerFailure, never Inactive."""
        with self.motions.no_new_motion():
            stopped = self.motions.stop_for_safety(timeout)
            if not stopped:
                log.error("the motion did not stop within %.1f s; disabling the drives now",
                          timeout)
            self._command_controller("disable")
            self._wait_controller(lambda: self._power is EnableState.DISABLED
                                  or self.link.lost is not None, self.enable_timeout)
            if self.link.lost is not None:
                raise ControllerFailure(f"the controller is lost: {self.link.lost}")
            if self._power is not EnableState.DISABLED:
                why = f"the drives did not go off within {self.enable_timeout:g} s ({reason})"
                self.fault(alarms.CONTROLLER, why)
                raise ControllerFailure(why)
            with self._state_lock:
                if self._state in states.ACTIVE:
                    self._transition(states.ACTIVE, State.INACTIVE, reason)

    def reset(self) -> State:
        """Leave Error once its cause is cleared; a lost controller is started afresh."""
        if self.link.lost is not None:
            self.bus.alarm(Severity.INFO, alarms.CONTROLLER_LOST, "restarting the controller")
            last = self.link.feedback.head
            self.link.restart()
            self._start_controller(30.0, after=last)
            self.on_health(True)
            if self._estop:   # the new controller found the button as it was left
                self._error = "e-stop pressed"
        if self._estop:
            raise EstopActive("the e-stop is still pressed: release it, then reset")
        with self._state_lock:
            if self._state is not State.ERROR:
                return self._state
            target = State.INACTIVE if self._holder else State.UNLOCKED
            self._transition({State.ERROR}, target, "reset")
            self._error = ""
            return target

    def post_message(self, text: str):
        """A message for the operator on the event stream, from the lock holder."""
        holder = self._holder
        return self.bus.operator_message(text, holder.client_name if holder else "")

    def operate_panel(self, action: str) -> tuple[bool, bool]:
        """Press or release the e-stop, open or close the door, as a person at the cell would
        (`action` names a Panel method); returns (e-stop pressed, door open)."""
        log.warning("operator panel: %s", action)
        try:
            estop, door_open = self.link.between_cycles(panel.operate, action, urgent=True)
        except (CycleProcessError, TimeoutError) as error:
            raise ControllerFailure(f"the operator panel did not answer: {error}") from None
        # Returns once the device has seen the e-stop as it is now (the next cycle's report).
        self._wait_controller(lambda: self._estop == estop or self.link.lost is not None, 1.0)
        return estop, door_open

    def _command_controller(self, method: str) -> None:
        try:
            result = getattr(self.controller, method)()
        except (CycleProcessError, TimeoutError) as error:
            raise ControllerFailure(f"the controller did not answer {method}: {error}") from None
        if result is not Status.OK:
            raise ControllerFailure(f"the controller refused {method}")

    def _wait_controller(self, done: Callable[[], bool], timeout: float) -> bool:
        with self._controller_changed:
            return self._controller_changed.wait_for(done, timeout)

    # ---- 3.2 settings, 3.3 queries ---------------------------------------------------------

    def update_settings(self, change) -> MotionSettings:
        """Apply `change(settings) -> settings`: validated, stored, then in force; a validation
        or storage error leaves them as they were."""
        with self._settings_lock:   # not the state lock: the file may keep us waiting
            settings = change(self._settings)
            self._store.save_settings(stored_settings.to_record(settings))
            self._settings = settings
            return settings

    def feedback(self) -> Sample:
        """The newest cycle's feedback (never more than a cycle old)."""
        sample = self.link.feedback.latest()
        if sample is None:
            raise ControllerFailure("no feedback from the controller yet")
        return sample

    def motion_control_state(self) -> tuple[str, str]:
        with self._state_lock:
            if self._state is State.ERROR:
                return states.ROBOT_STOPPED_ON_ERROR, states.CONTROLLER_ERROR
            power = states.POWER_ON if self._power is EnableState.ENABLED else states.POWER_OFF
            return self.motions.motion_state, power
