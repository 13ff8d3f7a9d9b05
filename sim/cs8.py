"""The simulated CS8's side of the LLI (Staubli LLI s7.4), shared by the simulated backends: the
pybullet one (bullet_controller.py, physics) and the kinematic one (kinematic.py, none).

`step()` is the drive interrupt: a cycle of the plant (`_advance`), then the cyclic function
(which calls `get()` then `set()`). Clocks call `step()`; nothing here depends on wall time.
`time` is simulated s since construction; `wall_time` the unix s of the latest cycle's tick.

Power (LLI 5.3.3, 5.3.4, 5.3.10). DISABLED means brakes on. ENABLING (enable_time) and
DISABLING (disable_time) hold the measured position with the drives; once ENABLED the held
command is the measured position. An invalid set(), a failing cyclic function (an exception or
False) or the e-stop disable at once, with an error event. While not ENABLED, set() is accepted
and ignored: there is nothing to command. Single-threaded: call everything from the thread that
steps (the cycle process).
"""
from __future__ import annotations

import logging
import time
from typing import Any

import numpy as np

from landscape.robot.cell import PANEL_WIRES, Cell
from landscape.robot.controller import (
    PANEL_ACTIONS, CalibState, Capability, Controller, CyclicFunction, DioStatus, DoutValue,
    EnableState, EstopState, EventFunc, InitState, IoctrlCode, IoId, IoType, IoUnit, JointCmd,
    JointFbk, SensorInfo, State, Status)
from landscape.robot.kinematics import Config, Kinematics, ReversingResult
from landscape.sim.command_checks import CommandChecks
from landscape.sim.dio import DigitalIO
from landscape.sim.panel import Panel

log = logging.getLogger(__name__)

SOFTWARE_VERSION = "landscape-sim CS8 LLI s7.4 0.1"
SYNCHRO_TASK_PRIORITY = 10     # VxWorks-style, 0 is highest; fixed, as on a CS8


class SimulatedCS8(Controller):
    """The LLI of `cell`'s controller over a plant: `drives` (bullet_drives.Drives, or
    kinematic.KinematicDrives), `sensors` (name -> read(), tare()), and the `world` the panel
    moves parts in (None: none). Besides the LLI: `cycle_time`, `time`, `step()`, `cyclic`
    (replaceable between cycles), `panel`, `dio` (I/O by name and unit), `last_record_path`."""

    def __init__(self, cell: Cell, drives, sensors: dict, world=None,
                 cyclic: CyclicFunction | None = None):
        self.cell = cell
        spec, arm = cell.controller, cell.arm
        self.cycle_time = spec.cycle_time
        self.cycles = 0
        self.time = 0.0
        self.wall_time = 0.0   # unix s at which the latest cycle began (its tick)
        self.cyclic = cyclic
        self._event_func: EventFunc | None = None

        self.panel = Panel(world, self._on_estop)
        self.dio = DigitalIO(cell.io, self._read_wire, self._write_world)
        self._sensors = sensors
        self._io_map = tuple(
            IoUnit(u.id, u.name, u.direction,
                   tuple(sorted((s.bit, s.name) for s in cell.io.signals if s.unit == u.id)))
            for u in cell.io.units)
        self._kin = Kinematics(arm)
        self._recorder = None
        self.last_record_path: str | None = None
        self._drives = drives   # braked

        self._checks = CommandChecks(arm, spec, drives.effort)
        self._enable_cycles = max(1, round(spec.enable_time / self.cycle_time))
        self._disable_cycles = max(1, round(spec.disable_time / self.cycle_time))
        self._user_marks = np.array(spec.user_marks)

        # LLI state.
        self._init = InitState.NOT_INITIALIZED
        self._calib = CalibState.NOT_CALIBRATED
        self._enable = EnableState.DISABLED
        self._countdown = 0
        self._torque_mode = False
        self._cyclic_failing = False
        self._destroyed = False
        self._state_was: tuple = ()
        # A press not yet seen by a cycle: reported until the next cycle has run, so a release
        # served before any cycle (both between the same two) does not hide the e-stop from
        # the cyclic function, as a safety relay holds a short press.
        self._estop_unseen = False
        self._state = State()

    # ---- the cycle ----------------------------------------------------------------------------

    def step(self) -> None:
        """One cycle: power procedures, cycle_time of physics and its feedback, world, recorder,
        then the cyclic function."""
        if self._destroyed:
            raise RuntimeError("the controller was destroyed")
        self.wall_time = time.time()
        if self._countdown:
            self._procedure()
        drives = self._drives
        self._advance()
        self.cycles += 1
        self.time = self.cycles * self.cycle_time
        if self._recorder is not None:
            fbk = drives.fbk
            self._recorder.append(self.time, *drives.reference(), fbk.pos, fbk.vel, fbk.torque)
        if self.cyclic is not None:
            self._run_cyclic()
        self._estop_unseen = False

    def _run_cyclic(self) -> None:
        try:
            ok = self.cyclic(self)
            why = "the cyclic function returned an error"
        except Exception as exc:  # noqa: BLE001 - any failure of user code disables the drives
            ok = False
            why = f"the cyclic function raised {type(exc).__name__}: {exc}"
        if ok is False:
            if self._enable is not EnableState.DISABLED or not self._cyclic_failing:
                self._event(f"{why}; drives disabled")
            self._cyclic_failing = True
            self._power_off()
        else:
            self._cyclic_failing = False

    def _procedure(self) -> None:
        """Advance enabling or disabling by one cycle."""
        self._countdown -= 1
        if self._countdown:
            return
        if self._enable is EnableState.ENABLING:
            self._enable = EnableState.ENABLED
            self._drives.engage(self._torque_mode)
        elif self._enable is EnableState.DISABLING:
            self._power_off()

    def _power_off(self) -> None:
        self._countdown = 0
        self._enable = EnableState.DISABLED
        if not self._drives.braked:
            self._drives.brake()

    # ---- the plant (the subclass's): a cycle of it, the world's wires, letting it go -----------

    def _advance(self) -> None:
        self._drives.cycle()

    def _read_world(self, wire: str) -> bool:   # an input wired to the world
        return False

    def _write_world(self, wire: str, value: bool) -> None:   # an output wired to the world
        pass

    def _disconnect(self) -> None:
        pass

    # ---- beyond the LLI: the operator panel, the world ---------------------------------------

    def capabilities(self) -> frozenset[Capability]:
        return frozenset({Capability.PANEL})

    def operate_panel(self, action: str) -> tuple[bool, bool]:
        if action not in PANEL_ACTIONS:
            raise ValueError(f"no panel action {action!r} (actions: {', '.join(PANEL_ACTIONS)})")
        getattr(self.panel, action)()
        return self.panel.estop_pressed, not self.panel.door_closed

    # ---- LLI: life cycle and power ------------------------------------------------------------

    def _event(self, text: str) -> None:
        log.warning("%s", text)
        if self._event_func is not None:
            try:
                self._event_func(text)
            except Exception:  # noqa: BLE001 - a broken listener must not break the controller
                log.exception("the event function raised")

    def _refuse(self, text: str) -> Status:
        self._event(text)
        return Status.ERROR

    def plug_event_func(self, func: EventFunc | None) -> Status:
        self._event_func = func
        return Status.OK

    def init(self) -> Status:
        if self._destroyed:
            return Status.ERROR
        if self._init is InitState.INITIALIZED:
            return self._refuse("init refused: already initialised (once per construction)")
        self._init = InitState.INITIALIZED
        return self.home()

    def home(self) -> Status:
        if self._init is not InitState.INITIALIZED:
            return self._refuse("home refused: not initialised")
        self._calib = CalibState.CALIBRATED
        return Status.OK

    def destroy(self) -> Status:
        if not self._destroyed:
            self._power_off()
            self._disconnect()
            self._destroyed = True
            self._init = InitState.NOT_INITIALIZED
            self._recorder = None
        return Status.OK

    def __enter__(self) -> "SimulatedCS8":
        return self

    def __exit__(self, *exc) -> None:
        self.destroy()

    def enable(self) -> Status:
        if self._init is not InitState.INITIALIZED or self._calib is not CalibState.CALIBRATED:
            return self._refuse("enable refused: the controller is not initialised")
        if self.panel.estop_pressed:
            return self._refuse("enable refused: the emergency stop is pressed; release it first")
        if self._enable is EnableState.DISABLING:
            return self._refuse("enable refused: the drives are disabling")
        if self._enable is EnableState.DISABLED:
            self._enable = EnableState.ENABLING
            self._countdown = self._enable_cycles
            self._drives.power_on()
        return Status.OK

    def disable(self) -> Status:
        if self._init is not InitState.INITIALIZED:
            return self._refuse("disable refused: the controller is not initialised")
        if self._enable in (EnableState.ENABLED, EnableState.ENABLING):
            self._enable = EnableState.DISABLING
            self._countdown = self._disable_cycles
            self._drives.hold()
        return Status.OK

    def _on_estop(self, pressed: bool) -> None:
        self._estop_unseen |= pressed
        if not pressed:
            self._event("emergency stop released")
        elif self._enable is EnableState.DISABLED:
            self._event("emergency stop pressed")
        else:
            self._power_off()
            self._event("emergency stop pressed: drives disabled")

    def state(self) -> State:
        now = (self._init, self._enable, self._calib, self._drives.settle,
               EstopState.ESTOP if self.panel.estop_pressed or self._estop_unseen
               else EstopState.NO_ESTOP)
        if now != self._state_was:   # the same (frozen) State while nothing changed: a
            self._state_was, self._state = now, State(*now)   # cyclic function asks each cycle
        return self._state

    # ---- LLI: the synchronous calls -----------------------------------------------------------

    def get(self) -> JointFbk:
        f = self._drives.fbk
        return JointFbk(f.pos.copy(), f.vel.copy(), f.pos_err.copy(), f.torque.copy())

    def set(self, cmd: JointCmd) -> Status:
        if self._enable is not EnableState.ENABLED:
            return Status.OK
        drives = self._drives
        command = self._checks.check(cmd, drives.cmd_pos, drives.cmd_vel)
        if isinstance(command, str):
            return self._reject(command)
        drives.command(*command)
        return Status.OK

    def _reject(self, problem: str) -> Status:
        """LLI 5.3.6: an invalid command is never applied; the drives are disabled."""
        self._power_off()
        self._event(f"set refused: {problem}; drives disabled")
        return Status.ERROR

    # ---- LLI: ioctrl --------------------------------------------------------------------------

    def ioctrl(self, code: IoctrlCode, data: Any = None) -> Any:
        """GET_*: the value (s, rad; joint range: (min (6,), max (6,))); SET_*: a Status."""
        try:
            code = IoctrlCode(code)
        except ValueError:
            return self._refuse(f"ioctrl refused: unknown code {code!r}")
        arm = self.cell.arm
        answers = {IoctrlCode.GET_SOFTWARE_VERSION: lambda: SOFTWARE_VERSION,
                   IoctrlCode.GET_ROBOT_TYPE: lambda: arm.name,
                   IoctrlCode.GET_JNT_NUMBER: lambda: 6,
                   IoctrlCode.GET_CYCLE_TIME: lambda: self.cycle_time,
                   IoctrlCode.GET_SYNCHRO_TASK_PRIORITY: lambda: SYNCHRO_TASK_PRIORITY,
                   IoctrlCode.GET_JNT_RANGE: lambda: (arm.lower.copy(), arm.upper.copy()),
                   IoctrlCode.GET_USER_MARKS: lambda: self._user_marks.copy()}
        if code in answers:
            return answers[code]()
        if code is IoctrlCode.SET_USER_MARKS:
            marks = np.asarray(data, dtype=float) if data is not None else np.empty(0)
            if marks.shape != (6,) or not np.all(np.isfinite(marks)):
                return self._refuse("ioctrl SET_USER_MARKS refused: needs 6 finite values (rad)")
            self._user_marks = marks.copy()
            return Status.OK
        if code is IoctrlCode.SET_TORQUE_MODE or code is IoctrlCode.SET_POS_VEL_MODE:
            torque = code is IoctrlCode.SET_TORQUE_MODE
            if torque != self._torque_mode:
                self._torque_mode = torque
                if self._enable is EnableState.ENABLED:
                    self._drives.engage(torque, bumpless=True)
            return Status.OK
        # SET_ABS_JNT_POS, RECOVER_ABS_JNT_POS: a simulated arm never loses its calibration.
        return self._refuse(f"ioctrl {code.name} refused: not supported by the simulated CS8")

    # ---- LLI: digital I/O by name -------------------------------------------------------------

    def _read_wire(self, wire: str) -> bool:
        return self.panel.read(wire) if wire in PANEL_WIRES else self._read_world(wire)

    def get_din_id(self, name: str) -> IoId:
        s = self.dio.lookup(name)
        found = s is not None and s.direction == "input"
        return IoId(IoType.D_INPUT, name) if found else IoId(IoType.UNDEFINED)

    def get_dout_id(self, name: str) -> IoId:
        s = self.dio.lookup(name)
        found = s is not None and s.direction == "output"
        return IoId(IoType.D_OUTPUT, name) if found else IoId(IoType.UNDEFINED)

    def read_dio(self, io: IoId) -> DioStatus:
        if io.type not in (IoType.D_INPUT, IoType.D_OUTPUT) or self.dio.lookup(io.name) is None:
            return DioStatus.UNDEFINED
        return DioStatus.ONE if self.dio.read(io.name) else DioStatus.ZERO

    def write_dout(self, io: IoId, value: DoutValue) -> Status:
        s = self.dio.lookup(io.name) if io.type is IoType.D_OUTPUT else None
        if s is None or s.direction != "output":
            return self._refuse(f"write_dout refused: {io.name!r} is not a digital output")
        self.dio.write(io.name, value == DoutValue.ONE)
        return Status.OK

    # ---- cell: I/O by unit, sensors ------------------------------------------------------------

    def io_map(self) -> tuple[IoUnit, ...]:
        return self._io_map

    def read_io_unit(self, unit: int, mask: int = -1) -> int:
        return self.dio.read_unit(unit, mask)

    def write_io_unit(self, unit: int, bits_on: int, bits_off: int) -> Status:
        try:
            self.dio.write_unit(unit, bits_on, bits_off)
        except (KeyError, ValueError) as exc:
            return self._refuse(f"write_io_unit refused: {exc.args[0]}")
        return Status.OK

    def sensor_map(self) -> tuple[SensorInfo, ...]:
        return tuple(SensorInfo(s.name, s.kind) for s in self.cell.sensors)

    def _sensor(self, name: str):
        try:
            return self._sensors[name]
        except KeyError:
            raise KeyError(f"no sensor {name!r} (sensors: {', '.join(self._sensors)})") from None

    def read_sensor(self, name: str) -> np.ndarray:
        """The present reading of a sensor of the cell (shape and units: sim/sensors.py)."""
        return self._sensor(name).read()

    def tare_sensor(self, name: str) -> Status:
        """Zero a sensor at its present reading."""
        self._sensor(name).tare()
        return Status.OK

    # ---- LLI: kinematics (flange in the base_link frame) --------------------------------------

    def forward_kin(self, joints: np.ndarray) -> tuple[np.ndarray, Config]:
        """LLI_forwardKin: the flange pose (4, 4) in base_link and the configuration of q (6,)."""
        return self._kin.forward(joints), self._kin.configuration(joints)

    def reverse_kin(self, joints_in: np.ndarray, target: np.ndarray, config: Config,
                    joint_range: tuple[np.ndarray, np.ndarray] | None = None
                    ) -> tuple[np.ndarray | None, ReversingResult]:
        """LLI_reverseKin: joints reaching `target` (flange (4, 4) in base_link) in `config`,
        nearest `joints_in`, within `joint_range` (min (6,), max (6,); default: the cell's)."""
        lower, upper = joint_range if joint_range is not None else (None, None)
        return self._kin.reverse(target, joints_in, config, lower, upper)

    # ---- LLI: recorder ------------------------------------------------------------------------

    def rec_init(self) -> Status:
        from landscape.sim.recorder import Recorder   # the recorder and mcap load on first use

        spec = self.cell.recorder
        self._recorder = Recorder(spec.path, spec.every_nth, spec.max_seconds, 6,
                                  cycle_time=self.cycle_time, arm=self.cell.arm)
        return Status.OK

    def rec_start(self) -> Status:
        return self._recording("rec_start", lambda recorder: recorder.start())

    def rec_stop(self) -> Status:
        return self._recording("rec_stop", lambda recorder: recorder.stop())

    def rec_store(self) -> Status:
        def store(recorder) -> None:
            self.last_record_path = recorder.store()
        return self._recording("rec_store", store)

    def _recording(self, call: str, act) -> Status:
        if self._recorder is None:
            return self._refuse(f"{call} refused: call rec_init first")
        try:
            act(self._recorder)
        except OSError as exc:
            return self._refuse(f"{call} failed: {exc}")
        return Status.OK
