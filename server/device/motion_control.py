"""Motion orchestration: from a planned motion to the cycle and back (seed 3.4 to 3.6).

The device's state machine (state_machine.py) says when a motion may start; this module plans it
(moves.py, path_planning.py), hands it to the Executor in the cycle (executor.py) through
shared memory, follows the Executor's reports (started, marks, paused, done, failed, aborted),
publishes the command events and moves the state Resting <-> Moving <-> Paused (through the
state machine's compare-and-set). It is given what it uses: the state machine, the link to the
controller, the bus, the planner, the collision scene and the settings; path runs (load, move,
marks) are path_runs.py's.

Ordering: a motion is registered, handed over and only then is the state moved and "started"
published, all inside the state machine's `atomic()`, so a report can never overtake the start and no
state is announced before the action it names has happened. Stops are messages to the cycle
sent at once; `stop_now` waits for nothing at all.
"""
from __future__ import annotations

import contextlib
import itertools
import logging
import threading
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from landscape.robot.arm import ArmModel
from landscape.server.cycle.run_arrays import pack_run
from landscape.server.cycle.shared_array import SharedArrays
from landscape.server.device import states
from landscape.server.device.state_machine import MANUAL_OFF, StateMachine
from landscape.server.device.motion_settings import MotionSettings
from landscape.server.device.states import State
from landscape.server.device.stored_settings import SettingsKeeper
from landscape.server.errors import (CommandError, ControllerFailure, ManualControlMode,
                                     WrongState)
from landscape.server.events import alarms
from landscape.server.events.bus import EventBus, Phase, Severity
from landscape.server.link.clock import CycleProcessError
from landscape.server.link.controller_link import ControllerLink
from landscape.server.planning.collision import CheckResult, CollisionScene
from landscape.server.planning.moves import Planner
from landscape.server.planning.motion.trajectory import Trajectory
from landscape.server.planning.process import check_run
from landscape.server.planning.targets import Frame

log = logging.getLogger(__name__)

ENDED = ("done", "failed", "aborted")
AT_REST = ("paused", *ENDED)


@dataclass
class RunningMotion:
    """A non-blocking motion the executor plays; `tags` names its waypoints for tag events."""

    command_id: str
    command: str
    point_name: str
    tags: dict[int, tuple[str, int]]
    aux: dict[int, tuple[str, ...]] = field(default_factory=dict)   # run at marks
    arrays: SharedArrays | None = None
    phase: str = "running"        # running, paused, done, failed, aborted
    # The final report's message, from the report (sensor loops: guarded.py); may act on it.
    finish: Callable[[dict], str] | None = None
    report: dict = field(default_factory=dict)   # the final report, once it came
    appended: list = field(default_factory=list)   # SharedArrays of later pieces (_hand_on)


class MotionControl:
    def __init__(self, state: StateMachine, link: ControllerLink, bus: EventBus, arm: ArmModel,
                 planner: Planner, collisions: CollisionScene, settings: SettingsKeeper):
        self.state, self.link, self.bus, self.arm = state, link, bus, arm
        self.collisions, self.settings = collisions, settings
        self.planner = planner
        self.motion_state = states.ROBOT_IDLE
        self._motion: RunningMotion | None = None
        self._changed = threading.Condition()
        self._ids = itertools.count(1)
        self._holds = 0                 # no_new_motion() blocks in force
        self._appending = threading.Lock()   # an append and a motion's end, one at a time
        # A motion's marks (path_runs.py: tags and aux commands), as the cycle reports them.
        self.on_mark: Callable[[RunningMotion, int], None] = lambda motion, label: None

    @property
    def running_id(self) -> str:
        motion = self._motion
        return motion.command_id if motion else ""

    @property
    def running(self) -> RunningMotion | None:
        return self._motion

    # ---- 3.4 single motions ----------------------------------------------------------------

    def warm_up(self) -> None:
        """Check the arm where it holds against the cell: the process's first check builds the
        cell's model and imports what it uses (about 90 ms), at start rather than in the first
        move's handler."""
        q = self.planning_start()
        with contextlib.suppress(CommandError):
            self.check_collisions([Trajectory(self.planner.dt, np.array([q, q]),
                                              np.zeros((2, len(q))))], "the arm at rest")

    def planning_start(self) -> np.ndarray:
        """Where the next motion starts: the setpoint the arm holds, rad."""
        return self.link.sample().command

    def move(self, command: str, point_name: str, frame: Frame, values: np.ndarray,
             relative: bool, straight: bool, speed_percent: float | None,
             settings: MotionSettings | None = None) -> str:
        """Seed 3.4.1 moveAbsolute / moveRelative: plan, then start; values in SI (joints rad;
        x, y, z m and roll, pitch, yaw rad); `settings`: this move's (default: the device's).
        Nothing moves if planning fails."""
        trajectory = self.plan_move(frame, values, relative, straight, speed_percent, settings,
                                    f"{command} {point_name}".strip())
        return self.start(command, point_name, [trajectory], checked=True)

    def plan_move(self, frame: Frame, values: np.ndarray, relative: bool, straight: bool,
                  speed_percent: float | None, settings: MotionSettings | None = None,
                  what: str = "the move"):
        """move()'s trajectory, planned and checked against the cell (`what` names it in a
        collision), not started (SolvePose); raises what move() would refuse with."""
        trajectory = self.planner.move(self.planning_start(), settings or self.settings.current,
                                       frame, values, relative, straight, speed_percent)
        self.check_collisions([trajectory], what)
        return trajectory

    def move_arc(self, point_name: str, frame: Frame, via: np.ndarray, goal: np.ndarray,
                 relative: bool, speed_percent: float | None) -> str:
        """Seed 3.4.1 moveArc: the tool tip on the circle through the arc point to the goal."""
        trajectory = self.planner.arc(self.planning_start(), self.settings.current, frame, via,
                                      goal, relative, speed_percent)
        return self.start("MoveArc", point_name, [trajectory])

    # ---- starting ----------------------------------------------------------------------------

    def check_collisions(self, trajectories: list, what: str = "the motion", *,
                         allow=(), model=None) -> CheckResult:
        """planning_process.check_run against the cell as it is now (or `model`)."""
        return check_run(self.collisions, trajectories, what, allow=allow, model=model)

    def start(self, command: str, point_name: str, trajectories: list,
              tags: dict | None = None, aux: dict | None = None, *, allow=(),
              loops: dict | None = None, finish: Callable[[dict], str] | None = None,
              checked: bool = False) -> str:
        """Hand planned trajectories to the executor, to play back to back; Resting -> Moving.
        `tags` maps mark labels to (tag name, tag index) for tag events, `aux` to the aux
        commands run there; `allow` as in check_collisions, which runs first (unless the
        planning checked them: `checked`);
        `loops` adds the sensor loops of the run message (executor.py: "guard", "comply") and
        `finish(report) -> message` words its end. Returns the command id that the started /
        tag / done / failed events name (seed: CMD_STARTED_OK)."""
        return self.start_motion(command, point_name, trajectories, tags, aux, allow=allow,
                                 loops=loops, finish=finish, checked=checked).command_id

    def start_motion(self, command, point_name, trajectories, tags=None, aux=None, *, allow=(),
               loops=None, finish=None, checked=False, ahead=None) -> RunningMotion:
        """start(), returning the motion; `ahead`: (rows checked, brake rows) of a run checked
        (and timed: path_runs.py) as it plays."""
        if not checked:
            self.check_collisions(trajectories, f"{command} {point_name}".strip(), allow=allow)
        arrays = self.link.share(pack_run(trajectories, self.planner.dt))
        motion = RunningMotion(f"{command}-{next(self._ids)}", command, point_name, tags or {},
                               aux or {}, arrays, finish=finish)
        unchecked = {} if ahead is None else {"checked": ahead[0], "brake": ahead[1]}
        try:
            self._begin(motion, {"op": "run", "id": motion.command_id, "arrays": arrays,
                                 **self._ramps(), **(loops or {}), **unchecked})
        except BaseException:
            arrays.discard()
            raise
        return motion

    def start_jog(self, message: dict) -> RunningMotion:
        """A jog session (jogging.py) as a motion: Resting -> Moving until it ends."""
        motion = RunningMotion(f"Jog-{next(self._ids)}", "Jog", "", {})
        self._begin(motion, {**message, "op": "jog", "id": motion.command_id})
        return motion

    def play(self, command: str, point_name: str, trajectory, timeout: float) -> RunningMotion:
        """Start one planned motion and wait until it ends or pauses (for commands that move
        the arm in steps, tooling.py); the motion says how it ended."""
        motion = self.start_motion(command, point_name, [trajectory])
        self._wait(motion, AT_REST, timeout)
        return motion

    def _ramps(self) -> dict:
        settings = self.settings.current
        return {"acceleration": settings.joint_accelerations, "jerk": settings.joint_jerks,
                "stop_acceleration": np.asarray(self.arm.max_acceleration),
                "stop_jerk": np.asarray(self.arm.max_jerk)}

    def _begin(self, motion: RunningMotion, message: dict) -> None:
        """Register the motion, hand it to the cycle, then Moving and "started" (all under the
        state lock, so no report overtakes the start)."""
        command = motion.command
        with self.state.atomic() as state:
            state.check_epoch()
            if state.state is not State.RESTING or self._holds:
                raise WrongState(f"{command} needs the arm at rest, it is "
                                 f"{state.state.value}", state=state.state.value)
            if state.manual_control != MANUAL_OFF and command != "Jog":
                raise ManualControlMode(f"the arm is under manual control "
                                        f"({state.manual_control}): only Jog moves it; "
                                        f"ManualControl(off) first")
            self._motion = motion
            try:
                self.link.send(message)
            except CycleProcessError as error:
                self._motion = None
                raise ControllerFailure(f"the controller is gone: {error}") from None
            self.motion_state = states.RUNNING_TRAJECTORY
            state.transition({State.RESTING}, State.MOVING,
                             f"{command} {motion.point_name}".strip())
            self.bus.command(motion.command_id, command, Phase.STARTED, motion.point_name)

    @contextlib.contextmanager
    def no_new_motion(self):
        """While in force no motion starts (for powering down)."""
        with self.state.atomic():
            self._holds += 1
        try:
            yield
        finally:
            with self.state.atomic():
                self._holds -= 1

    # ---- 3.6 interruptions -----------------------------------------------------------------

    def stop_motion(self, timeout: float = 10.0, gentle: bool = False) -> None:
        """Seed 3.6.1: decelerate along the path and hold (Paused); blocks until at rest."""
        self.wait_at_rest(self.request_stop(gentle), timeout)

    def request_stop(self, gentle: bool = False) -> RunningMotion:
        """StopMotion's first half, which waits for nothing: the stop is on its way to the
        cycle when this returns (the running motion, for wait_at_rest). It brakes at the arm's
        full deceleration and jerk, or `gentle`, at the set ones (a jog ends at full)."""
        with self.state.atomic() as state:
            motion = self._motion
            if motion is None or state.state is not State.MOVING:
                raise WrongState("no motion is running", state=state.state.value)
            settings = self.settings.current
            self.send({"op": "stop", **({"acceleration": settings.joint_accelerations,
                                         "jerk": settings.joint_jerks} if gentle else {})})
            return motion

    def wait_at_rest(self, motion: RunningMotion, timeout: float = 10.0) -> None:
        if not self._wait(motion, AT_REST, timeout):
            raise ControllerFailure(f"the arm did not come to rest within {timeout:g} s")

    def resume_motion(self) -> None:
        """Seed 3.6.2: the stopped motion goes on along its path (Paused -> Moving)."""
        with self.state.atomic() as state:
            motion = self._motion
            if motion is None or motion.phase != "paused" or state.state is not State.PAUSED:
                raise WrongState("no paused motion to resume", state=state.state.value)
            self.send({"op": "resume"})
            motion.phase = "running"
            self.motion_state = states.RUNNING_TRAJECTORY
            state.transition({State.PAUSED}, State.MOVING, "resumed")
            self.bus.command(motion.command_id, motion.command, Phase.RESUMED, motion.point_name)

    def abort_motion(self, timeout: float = 10.0) -> None:
        """Seed 3.6.2: drop the stopped motion (and the queue); the arm stays where it is."""
        self.wait_ended(self.request_abort(), timeout)

    def request_abort(self) -> RunningMotion | None:
        """AbortMotion's first half, which waits for nothing (None: nothing was queued)."""
        motion = self._motion
        if motion is not None:
            self.send({"op": "abort"})
        return motion

    def wait_ended(self, motion: RunningMotion | None, timeout: float = 10.0) -> None:
        if motion is not None and not self._wait(motion, ENDED, timeout):
            raise ControllerFailure(f"the abort did not finish within {timeout:g} s")

    def stop_now(self) -> None:
        """Safety: tell the cycle to stop (at the arm's full deceleration); waits for nothing."""
        if self._motion is not None:
            with contextlib.suppress(CycleProcessError):
                self.link.send({"op": "abort"})

    def stop_for_safety(self, timeout: float) -> bool:
        """Stop and drop any motion; True once the arm is at rest (False: timed out)."""
        motion = self._motion
        if motion is None:
            return True
        self.stop_now()
        return self._wait(motion, ENDED, timeout)

    def fail_running(self, message: str) -> None:
        """The controller is gone: the running motion will not report again; it failed."""
        motion = self._motion
        if motion is not None:
            self.on_report({"op": "failed", "id": motion.command_id, "message": message})

    @contextlib.contextmanager
    def appending(self, motion: RunningMotion):
        """Yields whether `motion` still runs; it runs on (and what is appended to it is
        discarded with it) until the block ends."""
        with self._appending:
            yield self._motion is motion

    def send(self, msg: dict) -> None:
        """A message to the cycle (executor.py); ControllerFailure if it is gone."""
        try:
            self.link.send(msg)
        except CycleProcessError as error:
            raise ControllerFailure(f"the controller is gone: {error}") from None

    def _wait(self, motion: RunningMotion, phases, timeout: float) -> bool:
        with self._changed:
            return self._changed.wait_for(lambda: motion.phase in phases, timeout)

    # ---- the executor's reports --------------------------------------------------------------

    def on_report(self, msg: dict) -> None:
        """The executor's reports on the running motion (executor.py), in order."""
        motion = self._motion
        if motion is None or msg.get("id") != motion.command_id:
            log.warning("cycle report for no running motion: %r", msg)
            return
        op = msg["op"]
        if op == "started":
            return   # the state moved when the run was sent
        if op == "mark":
            self.on_mark(motion, msg["label"])
            return
        if op == "resumed":
            return   # the state moved when the resume was sent
        phase = {"paused": Phase.PAUSED, "done": Phase.DONE, "failed": Phase.FAILED,
                 "aborted": Phase.ABORTED}[op]
        warning = msg.get("message", "")   # the cycle's own words: a problem
        if op in ENDED:
            motion.report = msg
            if motion.finish is not None:
                msg = {**msg, "message": motion.finish(msg)}
        with self.state.atomic() as state:
            motion.phase = op
            if op == "paused":
                self.motion_state = states.ROBOT_PAUSED
                if state.state is State.MOVING:
                    state.transition({State.MOVING}, State.PAUSED, "stopped on command")
            else:
                self._motion = None
                self.motion_state = {"done": states.ROBOT_IDLE,
                                     "failed": states.ROBOT_STOPPED_ON_ERROR,
                                     "aborted": states.ROBOT_STOPPED_ON_COMMAND}[op]
                if state.state in (State.MOVING, State.PAUSED):
                    state.transition({State.MOVING, State.PAUSED}, State.RESTING,
                                     f"{motion.command} {op}")
            self.bus.command(motion.command_id, motion.command, phase, motion.point_name,
                             message=msg.get("message", ""))
        if op == "failed" or warning:  # seed 3.4.1: an error alarm names the command
            self.bus.alarm(Severity.ERROR if op == "failed" else Severity.WARNING,
                           alarms.MOTION, f"{motion.command} {motion.point_name}: "
                           f"{msg.get('message', op)}".strip(), motion.command_id)
        if op in ENDED:
            with self._appending:   # none appended after this
                for arrays in (motion.arrays, *motion.appended):
                    if arrays is not None:
                        arrays.discard()
        with self._changed:
            self._changed.notify_all()
