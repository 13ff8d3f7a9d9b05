"""The device: one robot's state machine, lock, power and safety, above its controller.

Every transport (gRPC servicers now; the CRCL gateway and the dashboard through gRPC) reaches
the robot through these methods, `motions` (motion_control.py) and `path_runs`
(path_runs.py). They take and return domain values in SI (api/convert.py does the units); they
raise CommandError subclasses (errors.py) and change nothing when they do.

The Device puts together what it is made of and is the one object the servicers hold: the
state machine (state_machine.py: the state, the lock holder, the lease, the epoch, power,
e-stop and error, every transition a compare-and-set), the motions (motion_control.py), the
path runs (path_runs.py), the drives (power.py), the safety actions (safety.py), the
sessions, the RSVP questions and the settings. Each part is given the narrow things it uses,
never the Device.

Concurrency:
- Mutating commands run one at a time (`command()`); the state and the lease are checked
  (again) once their turn has come. Commands that stop the arm (`immediate`: StopMotion,
  AbortMotion, Deactivate) do not wait for that turn.
- A lock that changes hands bumps the epoch; a command admitted under an older epoch cannot
  start a motion (the disconnect handler may run while it plans).
- Safety actions (lock holder gone, e-stop, controller lost) do not wait for any command: the
  controller is told at once, the waiting happens on the safety worker (safety.py).
"""
from __future__ import annotations

import contextlib
import logging
from dataclasses import dataclass
from typing import Callable

from landscape.robot.arm import ArmModel
from landscape.robot.controller import Capability, EnableState, InitState, Status, operate_panel
from landscape.robot.kinematics import Kinematics
from landscape.server.cycle.feedback import Sample
from landscape.server.device import states
from landscape.server.device.motion_control import MotionControl
from landscape.server.device.path_runs import PathRuns
from landscape.server.device.motion_settings import MotionSettings
from landscape.server.device.power import Power
from landscape.server.device.rsvp import RsvpBroker
from landscape.server.device.safety import SafetyActions
from landscape.server.device.sessions import Session, SessionRegistry
from landscape.server.device.state_machine import StateMachine
from landscape.server.device.states import State
from landscape.server.device.stored_settings import WRITE_BEHIND, SettingsKeeper
from landscape.server.errors import ControllerFailure, EstopActive, NotOffered, ParamError
from landscape.server.events import alarms
from landscape.server.events.bus import EventBus, Severity
from landscape.server.link.clock import CycleProcessError
from landscape.server.link.controller_link import ControllerLink
from landscape.server.planning.collision import CollisionScene
from landscape.server.planning.moves import Planner
from landscape.server.planning.paths import PathStore

log = logging.getLogger(__name__)


@dataclass(frozen=True)
class DeviceStatus:
    state: State
    locked: bool
    lock_holder: str
    error: str
    estop: bool
    manual_control: str
    command_id: str


class Device:
    def __init__(self, link: ControllerLink, bus: EventBus, arm: ArmModel, *,
                 collisions: CollisionScene, paths: PathStore | None = None,
                 outputs: set[str] = frozenset(), enable_timeout: float = 5.0,
                 keepalive_interval: float = 0.5, keepalive_timeout: float = 2.0,
                 reset_settings: bool = False, settings_delay: float | None = None):
        self.link = link
        self.bus = bus
        self.arm = arm
        self.kinematics = Kinematics(arm)
        # What is where in the cell, for checking motions before they start (collision/).
        self.collisions = collisions
        self.on_health: Callable[[bool], None] = lambda serving: None
        # The cell's other parts (workcell/assembly.py wires them): reports from the cycle by
        # "op", and what to do each time the controller has (re)started.
        self.report_handlers: dict[str, Callable[[dict], None]] = {}
        self.on_controller_start: list[Callable[[], None]] = []
        self.state_machine = StateMachine(bus)
        self.rsvp = RsvpBroker(bus)
        store = paths or PathStore()
        self.settings_keeper = SettingsKeeper(MotionSettings(arm), store, reset_settings,
                                              WRITE_BEHIND if settings_delay is None
                                              else settings_delay)
        planner = Planner(self.kinematics, link.cycle_time)
        self.motions = MotionControl(self.state_machine, link, bus, arm, planner, collisions,
                                     self.settings_keeper)
        self.path_runs = PathRuns(self.motions, link, bus, planner, collisions, store,
                                  self.settings_keeper, set(outputs))
        self.motions.on_mark = self.path_runs.mark
        self.power = Power(self.state_machine, self.motions, link, enable_timeout)
        self.safety_actions = SafetyActions(
            self.state_machine, self.power, self.motions, link, bus, self.rsvp, self.reset,
            lambda serving: self.on_health(serving), self.report_handlers)
        self.safety = self.safety_actions.worker
        self.sessions = SessionRegistry(self.safety_actions.session_ended, keepalive_interval,
                                        keepalive_timeout)

    @property
    def controller(self):
        return self.link.proxy

    # The timeouts tests shorten.
    @property
    def enable_timeout(self) -> float:
        return self.power.enable_timeout

    @enable_timeout.setter
    def enable_timeout(self, seconds: float) -> None:
        self.power.enable_timeout = seconds

    @property
    def rsvp_timeout(self) -> float:
        return self.rsvp.timeout

    @rsvp_timeout.setter
    def rsvp_timeout(self, seconds: float) -> None:
        self.rsvp.timeout = seconds

    # ---- life cycle ------------------------------------------------------------------------

    def start(self, timeout: float = 30.0) -> None:
        """Initialise and home the controller (LLI_init); Idle until then, Unlocked after."""
        self._start_controller(timeout)
        self.state_machine.initialised()

    def _start_controller(self, timeout: float, after: int = -1) -> None:
        """Initialise the controller and wait for its first cycle's feedback (a row after
        cycle `after`: the ring outlives a controller); power and e-stop are then its own."""
        self.controller.plug_event_func(self.safety_actions.controller_event)
        if self.controller.state().init is not InitState.INITIALIZED:
            if self.controller.init() is not Status.OK:
                raise ControllerFailure("the controller did not initialise")
        if not self.power.wait(lambda: self.link.feedback.head > after, timeout):
            raise ControllerFailure("no feedback from the controller")
        sample = self.link.feedback.latest()
        self.state_machine.controller_reported(sample.enable, sample.estop)
        self.motions.warm_up()
        for started in self.on_controller_start:
            started()

    def close(self, timeout: float = 5.0) -> None:
        """Leave the arm safe: the lock holder's session ends (the disconnect handler stops,
        deactivates and releases), then nothing more is accepted."""
        self.sessions.close()
        self.safety.wait_idle(timeout)
        self.safety.close()
        self.settings_keeper.close()     # the settings written behind, now
        self.path_runs.close()

    # ---- state -----------------------------------------------------------------------------

    @property
    def state(self) -> State:
        return self.state_machine.state

    @property
    def lock_holder(self) -> Session | None:
        return self.state_machine.holder

    @property
    def manual_control(self) -> str:
        return self.state_machine.manual_control

    @property
    def settings(self) -> MotionSettings:
        return self.settings_keeper.current

    @property
    def error(self) -> str:
        return self.state_machine.error

    def status(self) -> DeviceStatus:
        with self.state_machine.atomic() as s:
            holder = s.holder
            return DeviceStatus(s.state, holder is not None,
                                holder.client_name if holder else "", s.error, s.estop,
                                s.manual_control, self.motions.running_id)

    def admit(self, rpc: str, lease: str | None) -> None:
        """Refuse `rpc` now if the state or the caller does not allow it (changes nothing)."""
        self.state_machine.admit(rpc, lease)

    def command(self, rpc: str, lease: str | None):
        """Run the body of `rpc` if the state table allows it now, for this caller
        (StateMachine.command)."""
        return self.state_machine.command(rpc, lease)

    def command_if_free(self, rpc: str, lease: str | None):
        """`command` now if no other command holds the turn (StateMachine.command_if_free),
        for the settings' bodies: never while the settings are written through (a file
        write may wait)."""
        if self.settings_keeper.writes_through:
            return contextlib.nullcontext(False)
        return self.state_machine.command_if_free(rpc, lease)

    def check_holder(self, what: str, lease: str | None) -> None:
        self.state_machine.check_holder(what, lease)

    # ---- 3.1 lock, release, activate, deactivate --------------------------------------------

    def lock(self, session_id: str, secret: str) -> str:
        session = self.sessions.owned(session_id, secret)
        if session is None:
            raise ParamError(f"no open session {session_id!r} with that secret: open one with "
                             f"SessionService.Connect and pass its session_id and session_secret")
        return self.state_machine.take_lock(session)

    def release(self) -> None:
        self.state_machine.release_lock()

    def activate(self) -> None:
        self.power.activate()

    def deactivate(self) -> None:
        """Stop along the path (at the arm's full deceleration) if moving, then drives off."""
        self.power.power_down("deactivated")

    def reset(self) -> State:
        """Leave Error once its cause is cleared; a lost controller is started afresh."""
        if self.link.lost is not None:
            self.bus.alarm(Severity.INFO, alarms.CONTROLLER_LOST, "restarting the controller")
            last = self.link.feedback.head
            self.link.restart()
            self._start_controller(30.0, after=last)
            self.on_health(True)
            if self.state_machine.estop:   # the new controller found the button as it was left
                self.state_machine.set_error("e-stop pressed")
        if self.state_machine.estop:
            raise EstopActive("the e-stop is still pressed: release it, then reset")
        return self.state_machine.leave_error()

    def post_message(self, text: str):
        """A message for the operator on the event stream, from the lock holder."""
        holder = self.state_machine.holder
        return self.bus.operator_message(text, holder.client_name if holder else "")

    def operate_panel(self, action: str) -> tuple[bool, bool]:
        """Press or release the e-stop, open or close the door, as a person at the cell would
        (`action` names a Panel method); returns (e-stop pressed, door open)."""
        if Capability.PANEL not in self.link.capabilities:
            raise NotOffered("this cell's controller has no operator panel")
        log.warning("operator panel: %s", action)
        try:
            estop, door_open = self.link.between_cycles(operate_panel, action, urgent=True)
        except (CycleProcessError, TimeoutError) as error:
            raise ControllerFailure(f"the operator panel did not answer: {error}") from None
        # Returns once the device has seen the e-stop as it is now (the next cycle's report).
        self.power.wait(lambda: self.state_machine.estop == estop or self.link.lost is not None,
                        1.0)
        return estop, door_open

    # ---- safety, for the cell's parts and the link --------------------------------------------

    def fault(self, code: int, message: str) -> None:
        """Into Error with an alarm and the drives off (Power.fault)."""
        self.power.fault(code, message)

    def controller_lost(self, reason: str) -> None:
        self.safety_actions.controller_lost(reason)

    def on_cycle_message(self, msg: dict) -> None:
        self.safety_actions.on_cycle_message(msg)

    def controller_event(self, text: str) -> None:
        self.safety_actions.controller_event(text)

    # ---- 3.2 settings, 3.3 queries ---------------------------------------------------------

    def update_settings(self, change) -> MotionSettings:
        """Apply `change(settings) -> settings`: validated, in force, then stored behind
        (stored_settings.py); a validation error leaves them as they were."""
        return self.settings_keeper.update(change)

    def feedback(self) -> Sample:
        """The newest cycle's feedback (never more than a cycle old)."""
        return self.link.sample()

    def motion_control_state(self) -> tuple[str, str]:
        with self.state_machine.atomic() as s:
            if s.state is State.ERROR:
                return states.ROBOT_STOPPED_ON_ERROR, states.CONTROLLER_ERROR
            power = states.POWER_ON if s.power is EnableState.ENABLED else states.POWER_OFF
            return self.motions.motion_state, power
