"""The device server's cyclic function: the per-cycle part of the device, in the cycle process.

Every cycle (LLI 5.3.10) it reads the feedback, takes the server's messages, computes the
setpoint and sets it. While the drives are not enabled it commands the measured position, so
that enabling starts from where the arm is and never jumps (LLI 5.3.3).

A motion is a timed trajectory played one sample per cycle, stopped and resumed along its path
within the acceleration limits (playback.py). It may carry a sensor loop (force_loops.py): a
guard (moveReact) that stops it when a sensor crosses a threshold (on a force, the stop then
settles the force near the threshold), a compliance (comply) that shifts its setpoints to hold
a force. Instead of a motion, a jog session (jog_integrator.py) may integrate velocity
requests. The I/O image and watches are read every cycle (inputs.py), the sensors while a loop
or a reader of the rows needs them; the arm model's torques (arm_dynamics.py) go into watched
rows (feedback.py).

Every cycle's feedback goes into the feedback ring (feedback.py). Messages, plain dicts
(picklable, so they cross the process boundary):
  server -> cycle  {"op": "run", "id": str, "acceleration": (6,) rad/s^2 and "jerk": (6,)
                    rad/s^3 (ramps that resume: the set ones), "stop_acceleration" and
                    "stop_jerk" (stops, aborts and a guard's braking: the arm's own, or the set
                    ones where StopMotion asks for them),
                    "arrays": SharedArrays of run_arrays.pack_run, optional "guard": GuardSpec,
                    "comply": ComplySpec}: segments played in order; a mark reports its label
                    when its sample is passed
                   a run checked or timed as it plays (run_check.py) adds "checked" (rows
                    checked so far) and "brake" (rows a stop may take), then comes on with
                    {"op": "checked", "id", "rows", "all"}, {"op": "append", "id", "arrays",
                    "continues", "rows", "brake", "all"} (later pieces) or {"op": "refused",
                    "id", "message"} (brake along the path, then fail)
                   {"op": "comply", "id", "spec": ComplySpec}: compliance for the running motion
                   {"op": "stop", optional "acceleration", "jerk": this stop's limits}
                   {"op": "resume"}  {"op": "abort"}
                   {"op": "payload", "parameters": (10,)}: what the flange carries now
                    (arm_dynamics.py)
                   the jog messages (jog_integrator.py) and the I/O ones (inputs.py)
  cycle -> server  {"op": "controller", "enable": EnableState value, "estop": bool} on change
                   {"op": "started", "id", "wall_time"}  {"op": "mark", "id", "label",
                    "wall_time"} (wall_time: unix s of the cycle)
                   {"op": "paused", "id"}  {"op": "resumed", "id"}  {"op": "done", "id"}
                   {"op": "failed", "id", "message"}  {"op": "aborted", "id"}
                   a guarded motion's end adds "guard": {"event": "triggered" | "envelope" |
                   "full distance", "values": (3,), "position": (6,) rad} (at the trigger),
                   once triggered "rest": (3,) (the reading at rest), "peak": (3,) (the
                   reading furthest past the threshold since) and "settle": why the force did
                   not settle, if it did not; a compliant one's
                   "comply": {"offset": (3,) m, "force": (3,) N, "panic": code or None}
"""
from __future__ import annotations

import time

import numpy as np

from landscape.server.cycle.inputs import CycleSensors, IoMonitor
from landscape.server.cycle.cycle_record import CycleRecord
from landscape.server.cycle.feedback import FeedbackRing
from landscape.server.cycle.force_loops import (RANGE_KIND, Admittance, ForceSettle, ThresholdMonitor,
                                            vector)
from landscape.server.cycle.jerk_tracker import PositionTracker
from landscape.server.cycle.jog_integrator import JogIntegrator
from landscape.server.cycle.playback import Motion, brake
from landscape.server.cycle.run_arrays import Segments
from landscape.robot.arm import ArmModel
from landscape.robot.controller import Controller, EnableState, EstopState, JointCmd
from landscape.server.cycle.shared_array import SharedArrays

# At rest means: every joint this close to its command (rad) and this slow (rad/s); an arm that
# is not there after SETTLE_TIMEOUT (s) is reported anyway, with its following error. An arm in
# contact (a motion with a sensor loop) rests where the contact lets it: SETTLE_CONTACT (rad).
SETTLE_POSITION = 1e-5
SETTLE_CONTACT = 1e-3
SETTLE_VELOCITY = 1e-3
SETTLE_TIMEOUT = 1.0


class Executor:
    """The cyclic function. `ring` receives every cycle's feedback (feedback.py); reports go to
    the server through `mailbox`, in order, after that cycle's row. `arm`: the arm model for
    the loops that need its Jacobian (jog, comply), refused without it, and for the model
    torques (`gravity`: m/s^2 in the arm's base frame). `sensors`, `io` and `model_torques`
    replace or leave out those parts of the cycle (bench_cell_loops times it without them)."""

    def __init__(self, mailbox, cycle_time: float, ring: FeedbackRing | None = None,
                 arm: ArmModel | None = None, gravity=(0.0, 0.0, -9.81), *,
                 sensors: CycleSensors | None = None, io: IoMonitor | None = None,
                 model_torques: bool = True):
        self.mailbox = mailbox
        self.cycle_time = cycle_time
        self._hold: np.ndarray | None = None   # commanded position when not moving, rad
        self._motion: Motion | None = None
        self._jog: JogIntegrator | None = None
        self._arrays: SharedArrays | None = None   # the running motion's trajectory block
        self._last_state = None
        self._reports: list[dict] = []   # reports of this cycle, posted after its row
        self._last_setpoint: np.ndarray | None = None   # a compliant motion's, last cycle
        self._last_wanted = np.zeros(6)   # the velocity a sensor loop wanted, last cycle
        self._tracker: PositionTracker | None = None    # a sensor loop's setpoints (jerk)
        self._velocity = np.zeros(6)                    # the commanded velocity, last cycle
        self._no_torque = np.zeros(6)   # the commands' torque feed-forward (read-only)
        self._limits = None if arm is None else (np.asarray(arm.max_velocity),
                                                 np.asarray(arm.max_acceleration),
                                                 np.asarray(arm.max_jerk))
        self._sensors = sensors or CycleSensors()
        self._io = io or IoMonitor()
        self._wall = 0.0   # this cycle's time stamp (unix s)
        self._tip = dynamics = None
        if arm is not None:
            # pinocchio: only where it runs
            from landscape.server.cycle.arm_dynamics import ArmDynamics
            from landscape.server.cycle.tip_model import TipModel
            self._tip = TipModel(arm)
            dynamics = ArmDynamics(arm, gravity) if model_torques else None
        self._record = CycleRecord(ring, cycle_time, dynamics)

    @property
    def sequence(self) -> int:
        """The sequence number the next cycle's row gets."""
        return self._record.sequence

    def __call__(self, ctrl: Controller) -> bool:
        # The cycle's time stamp: its tick, when the controller says (a simulated one computes
        # physics first, which a real one does not), else now.
        self._wall = getattr(ctrl, "wall_time", None) or time.time()
        fbk = ctrl.get()
        state = ctrl.state()
        enabled = state.enable is EnableState.ENABLED
        while (msg := self.mailbox.poll()) is not None:
            self._handle(msg, fbk)
        whole = self._record.watched   # sensors, model torques: only where used (feedback.py)
        sensors = self._sensors.read(ctrl, self._record.sequence, whole or self._sensing())
        self._io.poll(ctrl, self._record.sequence, self._reports)
        if not enabled or self._hold is None:
            self._hold = fbk.pos.copy()
            if self._motion is not None and not enabled:
                self._end("failed", message="drives disabled during the motion")
            if self._jog is not None and not enabled:
                self._end_jog("failed", "drives disabled while jogging")
        if self._motion is not None:
            pos, vel = self._play(self._motion, fbk, sensors)
        elif self._jog is not None:
            pos, vel = self._jog.step()
            self._hold = pos.copy()
            if self._jog.finished:
                self._end_jog(*self._jog.ending)
        else:
            pos, vel = self._hold, np.zeros_like(self._hold)
        ctrl.set(JointCmd(pos, vel, self._no_torque))
        self._velocity = np.asarray(vel, dtype=float)
        model = self._record.model_torques(fbk, pos, whole)

        key = (state.enable, state.estop)
        if key != self._last_state:   # first, so the server knows the power before the rest
            self._last_state = key
            self._reports.insert(0, {"op": "controller", "enable": int(state.enable),
                                     "estop": state.estop is EstopState.ESTOP})
        self._record.write(ctrl, fbk, pos, state, self._wall, self._sensors.values,
                           self._io.image, model)
        for report in self._reports:
            self.mailbox.post(report)
        self._reports.clear()
        return True

    def set_payload(self, parameters) -> None:
        """What the flange carries now (10 dynamic parameters, arm_dynamics.py)."""
        self._record.set_payload(parameters)

    def _sensing(self) -> bool:   # the running motion's sensor loops read this cycle's sensors
        return (m := self._motion) is not None and (m.guard, m.compliance, m.force_settle,
                                                     m.stopped_by) != (None,) * 4

    def _play(self, motion: Motion, fbk, sensors) -> tuple[np.ndarray, np.ndarray]:
        if motion.stopped_by is not None:
            motion.note_peak(sensors)
        if motion.settling is None:
            motion.keep_to_checked()
            motion.advance()
            for label in motion.passed_marks():
                self._reports.append({"op": "mark", "id": motion.id, "wall_time": self._wall,
                                      "label": label})
            running = motion.target_rate == 1.0 and not motion.paused
            if running:
                self._watch(motion, fbk, sensors)
            if motion.s >= motion.last and not motion.next_segment():
                if not (motion.compliance is not None and motion.compliance.holding):
                    motion.settling = motion.end_as or "done"
            elif (motion.target_rate == 0.0 and motion.rate == 0.0 and not motion.paused
                  and not motion.awaiting):
                motion.settling = motion.end_as or ("aborted" if motion.abort_when_paused
                                                    else "paused")
            if motion.settling == "done" and self._settling_force(motion):
                motion.settling = None
            if motion.settling is None:
                # outlives the motion's arrays
                target = self._shifted(motion, sensors, running and motion.settling is None)
                if motion.compliance is not None or motion.force_settle is not None:
                    return self._tracked(target)
                self._hold = target
                return self._hold, motion.velocity()
            target = self._shifted(motion, sensors, False)
            if motion.compliance is not None or motion.force_settle is not None:
                self._tracked(target, resting=True)
            else:
                self._hold = target
        elif self._tracker is not None:
            self._tracked(self._last_setpoint, resting=True)
        # A sensor loop that ended with its setpoints moving: they come to rest on its last
        # target within the limits (not dead in a cycle) before the arm can count as settled.
        if self._tracker is not None and not self._tracker.at_rest:
            return self._hold, self._tracker.velocity.copy()
        # At the end of the motion or of a stop ramp: hold until the arm has settled there, so
        # "done" and "paused" mean the arm is at rest where the command says.
        motion.settle_cycles += 1
        error = float(np.max(np.abs(fbk.pos - self._hold)))
        in_contact = motion.compliance is not None or "guard" in motion.outcome
        tolerance = SETTLE_CONTACT if in_contact else SETTLE_POSITION
        settled = error < tolerance and float(np.max(np.abs(fbk.vel))) < SETTLE_VELOCITY
        if settled or motion.settle_cycles * self.cycle_time > SETTLE_TIMEOUT:
            note = {} if settled else {"message": f"not settled within {SETTLE_TIMEOUT:g} s "
                                                  f"(following error {error:.2e} rad)"}
            if motion.settling == "paused":
                motion.paused, motion.settling, motion.settle_cycles = True, None, 0
                self._reports.append({"op": "paused", "id": motion.id, **note})
            else:
                if "message" in motion.outcome and "message" in note:
                    note["message"] = f"{motion.outcome['message']}; {note['message']}"
                if motion.compliance is not None:
                    motion.outcome["comply"] = motion.compliance.summary(sensors)
                if motion.stopped_by is not None:
                    motion.outcome["guard"]["rest"] = motion.stopped_by.reading(sensors).tolist()
                self._end(motion.settling, **{**motion.outcome, **note})
        return self._hold, np.zeros_like(self._hold)

    # ---- sensor loops ----------------------------------------------------------------------

    def _watch(self, motion: Motion, fbk, sensors) -> None:
        """A running motion's sensor loops: a guard that fires, or a compliance that must stop,
        brake the motion at the arm's full deceleration."""
        guard = motion.guard
        if guard is not None:
            verdict = guard.check(sensors)
            if verdict is not None:
                event, values = verdict
                motion.guard = None
                if event == "triggered":
                    motion.stopped_by = guard
                else:
                    self._sensors.watch_range = False
                motion.outcome["guard"] = {"event": event, "values": values.tolist(),
                                           "position": fbk.pos.tolist()}
                if event == "envelope":
                    motion.outcome["message"] = (f"sensor reading {vector(values)} left its "
                                                 f"envelope")
                brake(motion, "done" if event == "triggered" else "failed")
        compliance = motion.compliance
        if compliance is not None and compliance.problem is not None and motion.end_as is None:
            motion.outcome["message"] = compliance.problem
            brake(motion, "failed")

    def _settling_force(self, motion: Motion) -> bool:
        """Whether a motion braked on a force threshold settles its force now (starting
        that once it is at a stop: ForceSettle)."""
        settle, guard = motion.force_settle, motion.stopped_by
        if guard is None or self._tip is None or not ForceSettle.wanted(guard.spec):
            return False
        if settle is None and not motion.unsettled:
            settle = motion.force_settle = ForceSettle(guard.spec, self._tip, self.cycle_time)
            self._last_setpoint = self._hold
        if settle is not None and not settle.finished and motion.unsettled:
            settle.stop(motion.unsettled)
        note = settle.note if settle is not None else motion.unsettled
        if note:
            motion.outcome["guard"]["settle"] = note
        return settle is not None and not settle.finished

    def _tracked(self, target: np.ndarray, resting: bool = False
                 ) -> tuple[np.ndarray, np.ndarray]:
        """A sensor loop's setpoint, reached within the arm's velocity, acceleration and jerk
        limits (jerk_tracker.py) from the state the last setpoints were in: the hand-over into
        the loop (a compliance starting, a guarded stop's force settling) is continuous;
        `resting`: the loop has ended, the setpoints come to rest on the target."""
        tracker, dt = self._tracker, self.cycle_time
        if tracker is None:
            past = self._record.setpoints
            acceleration = (np.zeros(6) if past is None
                            else (past[0] - 2.0 * past[1] + past[2]) / (dt * dt))
            tracker = self._tracker = PositionTracker(self._hold, dt, self._velocity,
                                                      acceleration)
            self._last_setpoint, self._last_wanted = target, self._velocity
        # The wanted motion's velocity over the last cycle and its change: at the target, at
        # the cycle's end, it moves at the first plus half the second. A state consistent so
        # is reached in one cycle, a smooth wanted motion followed exactly (not so, ruckig's
        # profile takes longer, lags, and a force loop through it rings).
        mean = np.zeros(6) if resting else (target - self._last_setpoint) / dt
        change = np.zeros(6) if resting else mean - self._last_wanted
        self._last_setpoint, self._last_wanted = target, mean
        tracker.step(target, mean + change / 2.0, *self._limits, change / dt)
        self._hold = tracker.position.copy()
        return self._hold, tracker.velocity.copy()

    def _shifted(self, motion: Motion, sensors, active: bool) -> np.ndarray:
        """The motion's setpoint now: planned, shifted by its compliance or its force settling
        if it has one."""
        planned = motion.position()
        if motion.force_settle is not None:
            return motion.force_settle.shift(planned, sensors)
        compliance = motion.compliance
        if compliance is None:
            return planned.copy()
        return compliance.shift(planned, sensors, active)

    def _attach(self, motion: Motion, msg: dict) -> None:
        """The run's sensor loops (a missing arm model refuses a compliance)."""
        guard, comply = msg.get("guard"), msg.get("comply")
        if guard is not None:
            motion.guard = ThresholdMonitor(guard)
            self._sensors.watch_range = guard.kind == RANGE_KIND
            motion.outcome["guard"] = {"event": "full distance"}
        if comply is not None:
            motion.compliance = Admittance(comply, self._tip, self.cycle_time)
            self._last_setpoint = motion.position().copy()

    # ---- messages ----------------------------------------------------------------------------

    def _handle(self, msg: dict, fbk) -> None:
        op, motion = msg.get("op"), self._motion
        if op in ("io_image", "watch", "unwatch"):
            self._io.handle(msg)
        elif op == "payload":
            self.set_payload(msg["parameters"])
        elif op in ("jog", "jog_velocity", "jog_clearance", "jog_end"):
            self._handle_jog(msg, fbk)
        elif op == "run":
            if motion is not None:
                self._end("aborted")
            self._arrays = msg["arrays"]
            self._motion = Motion({**msg, "segments": Segments(self._arrays.open())},
                                   self.cycle_time)
            self._motion.stop_limit = np.asarray(msg["stop_acceleration"], dtype=float)
            self._motion.stop_jerk = np.asarray(msg.get("stop_jerk", msg.get("jerk")), dtype=float)
            self._reports.append({"op": "started", "id": msg["id"], "wall_time": self._wall})
            if msg.get("comply") is not None and self._tip is None:
                self._end("failed", message="this controller has no arm model for comply")
            else:
                self._attach(self._motion, msg)
        elif op == "checked" and motion is not None and motion.id == msg["id"]:
            motion.checked_to(msg["rows"], msg["all"])
        elif op == "append" and motion is not None and motion.id == msg["id"]:
            motion.append(msg["arrays"], msg["continues"], msg["rows"], msg["brake"], msg["all"])
        elif op == "refused" and motion is not None and motion.id == msg["id"]:
            if motion.refuse(msg["message"]):
                self._end("failed", message=msg["message"])
        elif op == "comply" and motion is not None and motion.id == msg["id"]:
            if motion.compliance is None and self._tip is not None:
                self._attach(motion, {"comply": msg["spec"]})
        elif self._jog is not None and op in ("stop", "abort"):
            self._jog.end("aborted", f"{op} while jogging")
        elif op in ("stop", "abort") and motion is not None and motion.stopped_by is not None:
            motion.unsettled = f"{op} before the force settled"   # a guarded stop's: no more
        elif op == "stop" and motion is not None and not motion.paused and motion.settling is None:
            # At the run's stop limits, or the message's (StopMotion at the set deceleration).
            motion.stop(msg.get("acceleration"), msg.get("jerk"))
        elif op == "resume" and motion is not None and motion.paused:
            motion.resume()
            self._reports.append({"op": "resumed", "id": motion.id})
        elif op == "abort" and motion is not None:
            if motion.paused:
                self._end("aborted")
            elif motion.settling is None:  # never drop a moving arm: stop along the path first
                motion.abort_when_paused = True
                motion.stop()

    def _handle_jog(self, msg: dict, fbk) -> None:
        op, jog = msg["op"], self._jog
        if op == "jog":
            self._reports.append({"op": "started", "id": msg["id"], "wall_time": self._wall})
            if self._motion is not None or jog is not None or self._tip is None:
                why = ("this controller has no arm model for jogging" if self._tip is None
                       else "the arm is moving")
                self._reports.append({"op": "failed", "id": msg["id"], "message": why})
                return
            start = self._hold if self._hold is not None else fbk.pos
            self._jog = JogIntegrator(msg["id"], start, msg["limits"], self._tip,
                                      np.asarray(msg["tool_offset"], dtype=float),
                                      self.cycle_time, msg.get("guarded", False))
        elif jog is not None and op == "jog_velocity":
            jog.command(msg)
        elif jog is not None and op == "jog_clearance":
            jog.keep_clear(msg)
        elif jog is not None and op == "jog_end":
            jog.end("done")

    def _end_jog(self, how: str, message: str = "") -> None:
        self._reports.append({"op": how, "id": self._jog.id,
                              **({"message": message} if message else {})})
        self._jog = None

    def _end(self, how: str, **details) -> None:
        self._reports.append({"op": how, "id": self._motion.id, **details})
        self._motion = None
        self._tracker = None
        self._sensors.watch_range = False
        if self._arrays is not None:
            self._arrays.close()
            self._arrays = None

