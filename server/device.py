"""The device: one robot's state machine, lock, settings and safety, above its controller.

Every transport (gRPC servicers now; the CRCL gateway and the dashboard through gRPC) reaches
the robot through these methods. They take and return domain values in SI (convert.py does the
units); they raise CommandError subclasses (errors.py) and change nothing when they do.

Concurrency: mutating commands run one at a time under `_command_lock` (held through blocking
waits such as enabling); the state itself is guarded by the short `_state_lock`. Safety actions
(lock holder gone, e-stop, controller fault) do not wait for the command lock: they act on the
controller at once and move the state; a command in flight then finds the state changed.
"""
from __future__ import annotations

import contextlib
import itertools
import logging
import secrets
import threading
import time
from dataclasses import dataclass, field

import numpy as np

from landscape.server import states
from landscape.server.errors import (ControllerFailure, EstopActive, NotFound, NotLockHolder,
                                     ParamError, WrongState)
from landscape.server.events import EventBus, Phase, Severity
from landscape.server import aux_commands, path_planning
from landscape.server.moves import Planner
from landscape.server.paths import PathLibrary, PathStore
from landscape.server.targets import Frame
from landscape.server.rsvp import RsvpBroker
from landscape.server.sessions import Session, SessionRegistry
from landscape.server.settings import MotionSettings
from landscape.server.states import Lease, State
from landscape.sim.arm import ArmModel
from landscape.sim.controller import DoutValue, EnableState, EstopState, InitState, Status
from landscape.sim.kinematics import Kinematics

log = logging.getLogger(__name__)

# Alarm codes of the device (the seed's return codes are the negative ones).
ALARM_LOCK_HOLDER_LOST = 101
ALARM_ESTOP = 102
ALARM_CONTROLLER = 103
ALARM_MOTION = 104

ESTOP_RELEASED_QUESTION = "estop_released"   # RSVP to the lock holder: reset now?
RESET, STAY = "reset", "stay"


@dataclass(frozen=True)
class Feedback:
    """The latest cycle report: time (simulated s), joints (rad, rad/s), controller flags."""

    time: float
    position: np.ndarray
    velocity: np.ndarray
    command: np.ndarray      # the setpoint of that cycle, rad: where planning starts
    enable: EnableState
    estop: bool


@dataclass
class RunningMotion:
    """A non-blocking motion the executor plays; `tags` names its waypoints for tag events."""

    command_id: str
    command: str
    point_name: str
    tags: dict[int, tuple[str, int]]
    aux: dict[int, tuple[str, ...]] = field(default_factory=dict)   # run at marks
    phase: str = "running"   # running, paused, done, failed, aborted


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
    def __init__(self, link, bus: EventBus, arm: ArmModel, *, paths: PathStore | None = None,
                 outputs: set[str] = frozenset(), enable_timeout: float = 5.0,
                 keepalive_interval: float = 0.5, keepalive_timeout: float = 2.0):
        self.link = link
        self.controller = link.proxy
        self.bus = bus
        self.arm = arm
        self.kinematics = Kinematics(arm)
        self.enable_timeout = enable_timeout
        self.rsvp_timeout = 30.0
        self.rsvp = RsvpBroker(bus)
        self.sessions = SessionRegistry(self._session_ended, keepalive_interval, keepalive_timeout)
        self._state = State.IDLE
        self._holder: Session | None = None
        self._lease: str | None = None
        self._settings = MotionSettings(arm)
        self._feedback: Feedback | None = None
        self._feedback_changed = threading.Condition()
        self._error = ""
        self._motion_state = states.ROBOT_IDLE
        self._state_lock = threading.RLock()
        self._command_lock = threading.Lock()
        self.planner = Planner(self.kinematics, link.cycle_time)
        self._motion: RunningMotion | None = None
        self._motion_changed = threading.Condition()
        self._command_ids = itertools.count(1)
        self.last_tag = ("", "")   # (path name, tag name), for getTagId
        self.outputs = set(outputs)  # digital outputs aux commands may set
        self.paths = PathLibrary(paths or PathStore())

    # ---- life cycle ------------------------------------------------------------------------

    def start(self, timeout: float = 30.0) -> None:
        """Initialise and home the controller (LLI_init); Idle until then, Unlocked after."""
        self.controller.plug_event_func(self._controller_event)
        if self.controller.state().init is not InitState.INITIALIZED:
            if self.controller.init() is not Status.OK:
                raise ControllerFailure("the controller did not initialise")
        self._wait_for(lambda f: True, timeout, "the first feedback from the controller")
        estop = self.controller.state().estop is EstopState.ESTOP
        self._move_to(State.ERROR if estop else State.UNLOCKED,
                      "e-stop pressed at start-up" if estop else "controller initialised")
        if estop:
            self._error = "e-stop pressed"

    def close(self) -> None:
        self.sessions.close()   # runs the disconnect handler for the lock holder, if any
        self.paths.close()

    # ---- state -----------------------------------------------------------------------------

    @property
    def state(self) -> State:
        return self._state

    @property
    def settings(self) -> MotionSettings:
        return self._settings

    def status(self) -> DeviceStatus:
        with self._state_lock:
            feedback = self._feedback
            motion = self._motion
            return DeviceStatus(self._state, self._holder is not None,
                                self._holder.client_name if self._holder else "", self._error,
                                bool(feedback and feedback.estop), "off",
                                motion.command_id if motion else "")

    def _move_to(self, new: State, reason: str) -> None:
        with self._state_lock:
            old, self._state = self._state, new
        if old is not new:
            log.info("%s -> %s: %s", old.value, new.value, reason)
            self.bus.state_change(old.value, new.value, reason)

    @contextlib.contextmanager
    def command(self, rpc: str, lease: str | None):
        """Run the body of `rpc` if the state table allows it now, for this caller.

        Read-only RPCs run at once. Mutating ones run one at a time; the state and the lease
        are checked first, so a refused call changes nothing.
        """
        rule = states.RULES[rpc]
        if rule.lease is Lease.NONE:
            self._check_state(rpc, rule)
            yield
            return
        with self._command_lock:
            with self._state_lock:
                self._check_state(rpc, rule)
                self._check_lease(rpc, rule, lease)
            yield

    def _check_state(self, rpc: str, rule: states.Rule) -> None:
        if self._state not in rule.states:
            valid = ", ".join(sorted(s.value for s in rule.states))
            raise WrongState(f"{rpc} is not valid in state {self._state.value} (seed {rule.seed}: "
                             f"valid in {valid})", state=self._state.value)

    def _check_lease(self, rpc: str, rule: states.Rule, lease: str | None) -> None:
        if rule.lease is Lease.SESSION:
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
            self._holder, self._lease = session, secrets.token_urlsafe(24)
            self._move_to(State.INACTIVE, f"locked by {session.client_name}")
            return self._lease

    def release(self) -> None:
        with self._state_lock:
            holder = self._holder
            self._holder = self._lease = None
            if self._state is State.INACTIVE:  # in Error it stays there, unlocked, until Reset
                self._move_to(State.UNLOCKED, f"released by {holder.client_name}")

    def activate(self) -> None:
        self._command_controller("enable")
        self._wait_for(lambda f: f.enable is EnableState.ENABLED or f.estop, self.enable_timeout,
                       "the drives to enable")
        if self._feedback.estop or self._state is not State.INACTIVE:
            raise ControllerFailure(f"activation interrupted ({self._error or 'e-stop'})")
        self._move_to(State.RESTING, "activated")

    def deactivate(self) -> None:
        self.abort_motion()  # a moving arm stops along its path before the drives go off
        self._disable("deactivated")

    def _disable(self, reason: str) -> None:
        self._command_controller("disable")
        self._wait_for(lambda f: f.enable is EnableState.DISABLED, self.enable_timeout,
                       "the drives to disable")
        with self._state_lock:
            if self._state in states.ACTIVE:
                self._move_to(State.INACTIVE, reason)

    def reset(self) -> State:
        if self.controller.state().estop is EstopState.ESTOP:
            raise EstopActive("the e-stop is still pressed: release it, then reset")
        with self._state_lock:
            if self._state is not State.ERROR:
                return self._state
            self._error = ""
            target = State.INACTIVE if self._holder else State.UNLOCKED
            self._move_to(target, "reset")
        return target

    def operate_panel(self, action: str) -> tuple[bool, bool]:
        """Press or release the e-stop, open or close the door, as a person at the cell would
        (`action` names a Panel method); returns (e-stop pressed, door open)."""
        log.warning("operator panel: %s", action)
        return self.link.between_cycles(_operate_panel, action)

    def _command_controller(self, method: str) -> None:
        if getattr(self.controller, method)() is not Status.OK:
            raise ControllerFailure(f"the controller refused {method}")

    def _wait_for(self, done, timeout: float, what: str) -> None:
        deadline = time.monotonic() + timeout
        with self._feedback_changed:
            while self._feedback is None or not done(self._feedback):
                remaining = deadline - time.monotonic()
                if remaining <= 0:
                    raise ControllerFailure(f"timed out after {timeout:g} s waiting for {what}")
                self._feedback_changed.wait(remaining)

    # ---- 3.2 settings ------------------------------------------------------------------------

    def update_settings(self, change) -> MotionSettings:
        """Apply `change(settings) -> settings`; a validation error leaves them as they were."""
        with self._state_lock:
            self._settings = change(self._settings)
            return self._settings

    # ---- 3.3 queries ---------------------------------------------------------------------------

    def feedback(self) -> Feedback:
        feedback = self._feedback
        if feedback is None:
            raise ControllerFailure("no feedback from the controller yet")
        return feedback

    def tool_in_world(self, joints: np.ndarray) -> np.ndarray:
        """4x4 pose (m) of the tool tip in the world frame at these joints."""
        settings = self._settings
        flange = self.kinematics.forward(joints)
        return np.linalg.inv(settings.world_frame) @ flange @ settings.tool_offset

    def motion_control_state(self) -> tuple[str, str]:
        with self._state_lock:
            if self._state is State.ERROR:
                return states.ROBOT_STOPPED_ON_ERROR, states.CONTROLLER_ERROR
            feedback = self._feedback
            power = (states.POWER_ON if feedback and feedback.enable is EnableState.ENABLED
                     else states.POWER_OFF)
            return self._motion_state, power

    # ---- 3.4 - 3.6 motion --------------------------------------------------------------------------

    def planning_start(self) -> np.ndarray:
        """Where the next motion starts: the setpoint the arm holds, rad."""
        return self.feedback().command

    def move(self, command: str, point_name: str, frame: Frame, values: np.ndarray,
             relative: bool, straight: bool, speed_percent: float | None) -> str:
        """Seed 3.4.1 moveAbsolute / moveRelative: plan, then start; values in SI (joints rad;
        x, y, z m and roll, pitch, yaw rad). Nothing moves if planning fails."""
        trajectory = self.planner.move(self.planning_start(), self._settings, frame, values,
                                       relative, straight, speed_percent)
        return self.start_motion(command, point_name, [trajectory])

    def move_arc(self, point_name: str, frame: Frame, via: np.ndarray, goal: np.ndarray,
                 relative: bool, speed_percent: float | None) -> str:
        """Seed 3.4.1 moveArc: the tool tip on the circle through the arc point to the goal."""
        trajectory = self.planner.arc(self.planning_start(), self._settings, frame, via, goal,
                                      relative, speed_percent)
        return self.start_motion("MoveArc", point_name, [trajectory])

    def start_motion(self, command: str, point_name: str, trajectories: list,
                     tags: dict | None = None, aux: dict | None = None) -> str:
        """Hand planned trajectories to the executor, to play back to back; Resting -> Moving.
        `tags` maps mark labels to (tag name, tag index) for tag events, `aux` to the aux
        commands run there. Returns the command id that the started / tag / done / failed
        events name (seed: CMD_STARTED_OK)."""
        segments = [{"positions": t.positions, "velocities": t.velocities, "marks": list(t.marks)}
                    for t in trajectories]
        command_id = f"{command}-{next(self._command_ids)}"
        with self._state_lock:
            if self._state is not State.RESTING:  # an e-stop may have come while planning
                raise WrongState(f"{command} needs the arm at rest, it is {self._state.value}")
            self._motion = RunningMotion(command_id, command, point_name, tags or {}, aux or {})
            self._motion_state = states.RUNNING_TRAJECTORY
            self._move_to(State.MOVING, f"{command} {point_name}".strip())
        self.bus.command(command_id, command, Phase.STARTED, point_name)
        # Stop and resume ramps keep to the set acceleration, like the planned motion.
        self.link.send({"op": "run", "id": command_id, "segments": segments,
                        "acceleration": self._settings.joint_accelerations})
        return command_id

    def stop_motion(self, timeout: float = 10.0) -> None:
        """Seed 3.6.1: decelerate along the path and hold; blocks until the arm is at rest."""
        motion = self._motion
        self.link.send({"op": "stop"})
        self._wait_motion(motion, ("paused", "done", "failed", "aborted"), timeout, "the stop")

    def resume_motion(self) -> None:
        motion = self._motion
        with self._state_lock:
            motion.phase = "running"
            self._motion_state = states.RUNNING_TRAJECTORY
            self._move_to(State.MOVING, "resumed")
        self.link.send({"op": "resume"})
        self.bus.command(motion.command_id, motion.command, Phase.RESUMED, motion.point_name)

    def abort_motion(self, timeout: float = 10.0) -> None:
        """Seed 3.6.2: drop the stopped motion (and the queue); the arm stays where it is."""
        motion = self._motion
        if motion is None:
            return  # nothing queued: the queue is already clear
        self.link.send({"op": "abort"})
        self._wait_motion(motion, ("done", "failed", "aborted"), timeout, "the abort")

    def _wait_motion(self, motion: RunningMotion | None, phases, timeout: float, what: str) -> None:
        if motion is None:
            return
        with self._motion_changed:
            if not self._motion_changed.wait_for(lambda: motion.phase in phases, timeout):
                raise ControllerFailure(f"timed out after {timeout:g} s waiting for {what}")

    def _motion_event(self, msg: dict) -> None:
        """The executor's reports on the running motion (executor.py), in order."""
        motion = self._motion
        if motion is None or msg.get("id") != motion.command_id:
            log.warning("cycle report for no running motion: %r", msg)
            return
        op = msg["op"]
        if op == "mark":
            label = msg["label"]
            for command in motion.aux.get(label, ()):
                self._run_aux(motion, command)
            if label in motion.tags:
                name, index = motion.tags[label]
                self.last_tag = (motion.point_name, name)
                self.bus.command(motion.command_id, motion.command, Phase.TAG_REACHED,
                                 motion.point_name, name, index)
            return
        with self._state_lock:
            motion.phase = op if op != "resumed" else "running"
            if op == "paused":
                self._motion_state = states.ROBOT_PAUSED
                self._move_to(State.PAUSED, "stopped on command")
            elif op in ("done", "failed", "aborted"):
                self._motion = None
                self._motion_state = {"done": states.ROBOT_IDLE, "failed": states.ROBOT_STOPPED_ON_ERROR,
                                      "aborted": states.ROBOT_STOPPED_ON_COMMAND}[op]
                if self._state in (State.MOVING, State.PAUSED):
                    self._move_to(State.RESTING, f"{motion.command} {op}")
        phase = {"paused": Phase.PAUSED, "done": Phase.DONE, "failed": Phase.FAILED,
                 "aborted": Phase.ABORTED}.get(op)
        if phase is not None:
            self.bus.command(motion.command_id, motion.command, phase, motion.point_name,
                             message=msg.get("message", ""))
        if op == "failed" or msg.get("message"):  # seed 3.4.1: an error alarm names the command
            self.bus.alarm(Severity.ERROR if op == "failed" else Severity.WARNING,
                           ALARM_MOTION, f"{motion.command} {motion.point_name}: "
                           f"{msg.get('message', op)}".strip(), motion.command_id)
        with self._motion_changed:
            self._motion_changed.notify_all()

    # ---- 3.5 paths ---------------------------------------------------------------------------------

    def path_load(self, name: str, frame: Frame, straight: bool, relative: bool, specs,
                  total: int | None = None) -> tuple[int, int]:
        """Seed 3.5.1 pathLoad: resolve and check every point, then append them to the named
        queue in one transaction; nothing is stored if any point fails. Returns (points
        loaded, path length)."""
        path = path_planning.load(self.planner, self.paths.get(name), name, frame, straight,
                                  relative, specs, self._settings, self.outputs,
                                  self.planning_start(), total)
        self.paths.put(path)
        return len(specs), len(path.points)

    def path_clear(self, name: str) -> None:
        motion = self._motion
        if motion is not None and motion.point_name == name and motion.command == "PathMove":
            raise WrongState(f"path {name!r} is running; stop and abort it first")
        self.paths.delete(name)

    def path_move(self, name: str, cycles: int) -> str:
        """Seed 3.5.2 pathMove: `cycles` passes; 0 is a dry run without aux commands."""
        path = self.paths.get(name)
        if path is None:
            raise NotFound(f"no path named {name!r}")
        trajectories = path_planning.plan_run(self.planner, path, self.planning_start(),
                                              self._settings, cycles)
        tags = {i: (p.tag_name, p.tag_index) for i, p in enumerate(path.points) if p.tag_name}
        aux = {} if cycles == 0 else {i: p.aux_commands for i, p in enumerate(path.points)
                                      if p.aux_commands}
        return self.start_motion("PathMove", name, trajectories, tags, aux)

    def _run_aux(self, motion: RunningMotion, command: str) -> None:
        out = aux_commands.parse(command, self.outputs)
        io = self.controller.get_dout_id(out.name)
        if self.controller.write_dout(io, DoutValue.ONE if out.value else DoutValue.ZERO) \
                is not Status.OK:
            self.bus.alarm(Severity.WARNING, ALARM_CONTROLLER,
                           f"aux command {command!r} failed", motion.command_id)

    # ---- safety ----------------------------------------------------------------------------------

    def _session_ended(self, session: Session, reason: str) -> None:
        """The seed's disconnect handler (2.2): stop, deactivate and release."""
        self.rsvp.abandon(session)
        with self._state_lock:
            if self._holder is not session:
                return
            self._holder = self._lease = None
            was = self._state
        if was in states.ACTIVE:
            try:
                self.abort_motion()  # stop along the path, then drives off
            except ControllerFailure:
                log.error("the motion did not stop in time; disabling the drives now")
            self.controller.disable()
        if was is not State.ERROR:
            self._move_to(State.UNLOCKED, f"lock holder {session.client_name} gone: {reason}")
        self.bus.alarm(Severity.WARNING, ALARM_LOCK_HOLDER_LOST,
                       f"lock holder {session.client_name} disconnected ({reason}); motion "
                       f"stopped, drives off, lock released")

    def _fault(self, code: int, message: str) -> None:
        with self._state_lock:
            if self._state is State.ERROR:
                return
            self._error = message
        self.controller.disable()
        self._move_to(State.ERROR, message)
        self.bus.alarm(Severity.CRITICAL if code == ALARM_ESTOP else Severity.ERROR, code, message)

    def _controller_event(self, text: str) -> None:
        """The controller's event function (LLI 5.2.1): its errors fault the device."""
        log.warning("controller: %s", text)
        if self.controller.state().estop is EstopState.ESTOP:
            if self._state not in (State.ERROR, State.IDLE):
                self._fault(ALARM_ESTOP, "e-stop pressed: motion stopped, drives off")
        elif self._state in states.ACTIVE:
            self._fault(ALARM_CONTROLLER, f"controller error: {text}")
        else:
            self.bus.alarm(Severity.WARNING, ALARM_CONTROLLER, f"controller: {text}")

    def on_cycle_message(self, msg: dict) -> None:
        """The Executor's posts (executor.py), on the link's dispatch thread."""
        if msg.get("op") != "feedback":
            self._motion_event(msg)
            return
        feedback = Feedback(msg["time"], np.asarray(msg["position"]), np.asarray(msg["velocity"]),
                            np.asarray(msg["command"]), EnableState(msg["enable"]), msg["estop"])
        with self._feedback_changed:
            previous, self._feedback = self._feedback, feedback
            self._feedback_changed.notify_all()
        if feedback.estop and self._state not in (State.ERROR, State.IDLE):
            self._fault(ALARM_ESTOP, "e-stop pressed: motion stopped, drives off")
        elif previous and previous.estop and not feedback.estop and self._holder:
            threading.Thread(target=self._offer_reset, args=(self._holder,), daemon=True,
                             name="rsvp-estop-released").start()

    def _offer_reset(self, holder: Session) -> None:
        """The e-stop was released: ask the lock holder whether to reset now (default: stay)."""
        answer = self.rsvp.ask(holder, ESTOP_RELEASED_QUESTION, ("e-stop released; reset now?",),
                               (RESET, STAY), STAY, self.rsvp_timeout, alarm=True)
        if answer.choice == RESET and self._holder is holder:
            try:
                self.reset()
            except EstopActive as refused:  # pressed again meanwhile
                self.bus.alarm(Severity.WARNING, ALARM_ESTOP, str(refused))


def _operate_panel(controller, action: str) -> tuple[bool, bool]:
    """Runs between two cycles, where the simulator's panel lives (picklable: top level)."""
    panel = controller.panel
    getattr(panel, action)()
    return panel.estop_pressed, not panel.door_closed
