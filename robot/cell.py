"""The cell file: one TOML file configuring a simulated cell, read into typed tables (pydantic,
toml_tables.py) and made into the frozen dataclasses the simulator uses (cell_model.py, all of
them named here too).

Like the CS8's configuration files together (controller.cfx for the cycle time, cell.cf for the
named I/O, records.cfx for the recorder), plus what a simulator needs: the arm variant, the world
(floor, fixtures, tools, parts, zones) and the sensors. `robot/cells/default.toml` is the
reference, with every key commented.

Units: metres, kilograms, seconds, newtons; angles in degrees where the key ends in `_deg`,
radians everywhere else (so arm overrides such as `max_acceleration` are rad/s^2 and `max_jerk`
rad/s^3, as in `ArmModel`). Poses are `xyz` (m) plus `rpy_deg`, fixed-axis X-Y-Z (R = Rz(yaw)
Ry(pitch) Rx(roll), DESIGN.md section 6), in the world frame unless said otherwise. Unknown
keys are errors, so a typo never silently falls back to a default; every error names the file
and the key.
"""
from __future__ import annotations

import math
from importlib import resources
from pathlib import Path

from pydantic import model_validator

from landscape.robot.arm import VARIANTS, ArmModel, arm_model
from landscape.robot.backends import BACKENDS
from landscape.robot.cell_model import (  # noqa: F401  (the parsed cell, named here too)
    BoxSpec, Cell, ControllerSpec, INPUT_WIRES, IoSignalSpec, IoSpec, IoUnitSpec, MAX_BITS,
    MAX_TOOL_ID_BITS, OUTPUT_WIRES, PANEL_WIRES, Pose, RecorderSpec, SENSOR_KINDS, SensorSpec,
    TOOL_KINDS, ToolSpec, WORLD_INPUT_WIRES, WorldSpec, ZoneSpec)
from landscape.robot.controller import check_cycle_time
from landscape.robot.toml_tables import (Table, flag, integer, names, number, problem, read_toml,
                                       string, vector)

_DEG = math.pi / 180.0


class CellError(ValueError):
    """A cell file that cannot be used; the message names the file and the key."""


def _degrees(radians) -> tuple[float, ...]:
    return tuple(v / _DEG for v in radians)


def _radians(degrees) -> tuple[float, ...]:
    return tuple(v * _DEG for v in degrees)


Name = string()
Positive = number(above=0.0)
Vector3 = vector(3)
Size = vector(3, positive=True)
Joints = vector(6)
JointLimits = vector(6, positive=True)


# ---- the file's tables ------------------------------------------------------------------------

class ArmTable(Table):
    variant: string(tuple(VARIANTS)) = "TX90"
    base_xyz: Vector3 = (0.0, 0.0, 0.0)
    base_rpy_deg: Vector3 = (0.0, 0.0, 0.0)
    # Overrides of sim/arm.py, SI units; the joint ranges in degrees are the cell limits.
    max_velocity: JointLimits | None = None
    max_acceleration: JointLimits | None = None
    max_jerk: JointLimits | None = None
    max_effort: JointLimits | None = None
    max_linear_velocity: Positive | None = None
    max_angular_velocity: Positive | None = None
    max_linear_acceleration: Positive | None = None
    max_angular_acceleration: Positive | None = None
    joint_min_deg: Joints | None = None
    joint_max_deg: Joints | None = None

    def arm_model(self) -> ArmModel:
        overrides = {key: getattr(self, key) for key in self.model_fields_set
                     if key.startswith("max_")}
        overrides.update((key[:-4], _radians(getattr(self, key)))
                         for key in ("joint_min_deg", "joint_max_deg") if self.given(key))
        try:
            return arm_model(self.variant, **overrides)
        except ValueError as error:
            raise problem(str(error)) from None

    @model_validator(mode="after")
    def _consistent(self):
        self.arm_model()
        return self


class ControllerTable(Table):
    backend: string(tuple(BACKENDS)) = ControllerSpec.backend
    cycle_time: number(above=0.0, then=check_cycle_time) = ControllerSpec.cycle_time
    physics_step: Positive = ControllerSpec.physics_step
    enable_time: number(0.0, 10.0) = ControllerSpec.enable_time
    disable_time: number(0.0, 10.0) = ControllerSpec.disable_time
    acceleration_factor: number(low=1.0) = ControllerSpec.acceleration_factor
    effort_factor: Positive = ControllerSpec.effort_factor
    brake_factor: Positive = ControllerSpec.brake_factor
    initial_position_deg: Joints = _degrees(ControllerSpec.initial_position)
    user_marks_deg: Joints = (0.0,) * 6

    def spec(self) -> ControllerSpec:
        return ControllerSpec(self.cycle_time, self.physics_step, self.enable_time,
                              self.disable_time, self.acceleration_factor, self.effort_factor,
                              self.brake_factor, _radians(self.initial_position_deg),
                              _radians(self.user_marks_deg), self.backend)


class FixtureTable(Table):
    """A box fixed in the world: mass 0, or at least given as 0."""

    name: Name
    xyz: Vector3
    rpy_deg: Vector3 = (0.0, 0.0, 0.0)
    size: Size
    mass: number(low=0.0) = 0.0
    color: vector(4) = BoxSpec.color

    def spec(self) -> BoxSpec:
        return BoxSpec(self.name, Pose(self.xyz, _radians(self.rpy_deg)), self.size, self.mass,
                       self.color)


class PartTable(FixtureTable):
    mass: Positive
    color: vector(4) = (0.8, 0.3, 0.2, 1.0)


class ToolTable(Table):
    name: Name
    kind: string(TOOL_KINDS)
    xyz: Vector3
    rpy_deg: Vector3 = (0.0, 0.0, 0.0)
    mass: Positive
    length: Positive
    id: integer(1, 2 ** MAX_TOOL_ID_BITS - 1) | None = None   # default: its place in the rack
    stroke: Positive = ToolSpec.stroke                  # a parallel_gripper's
    finger_speed: Positive = ToolSpec.finger_speed      # a parallel_gripper's
    cup_radius: Positive = ToolSpec.cup_radius          # a vacuum_cup's
    contact_stiffness: Positive = ToolSpec.contact_stiffness
    contact_damping: Positive = ToolSpec.contact_damping

    @model_validator(mode="after")
    def _keys_of_its_kind(self):
        own = {"parallel_gripper": ("stroke", "finger_speed"), "vacuum_cup": ("cup_radius",)}
        for kind, keys in own.items():
            for key in keys:
                if self.given(key) and self.kind != kind:
                    raise problem(f"only a {kind} has a {key} (this tool is a {self.kind})", key)
        return self

    def spec(self, index: int) -> ToolSpec:
        return ToolSpec(self.name, self.kind, Pose(self.xyz, _radians(self.rpy_deg)), self.mass,
                        self.length, index + 1 if self.id is None else self.id, self.stroke,
                        self.finger_speed, self.cup_radius, self.contact_stiffness,
                        self.contact_damping)


class ZoneTable(Table):
    name: Name
    xyz: Vector3      # its centre
    size: Size

    def spec(self) -> ZoneSpec:
        return ZoneSpec(self.name, self.xyz, self.size)


class WorldTable(Table):
    gravity: Vector3 = WorldSpec.gravity
    floor: flag = WorldSpec.floor
    lock_distance: Positive = WorldSpec.lock_distance
    lock_angle_deg: Positive = WorldSpec.lock_angle / _DEG
    fixtures: list[FixtureTable] = []
    tools: list[ToolTable] = []
    parts: list[PartTable] = []
    zones: list[ZoneTable] = []

    @model_validator(mode="after")
    def _unique(self):
        names(self.fixtures + self.parts, "fixtures or parts", "parts")
        names(self.tools, "tools", "tools")
        ids = [tool.spec(i).id for i, tool in enumerate(self.tools)]
        if len(set(ids)) != len(ids):
            raise problem("two tools share an id", "tools")
        names(self.zones, "zones", "zones")
        return self

    def spec(self) -> WorldSpec:
        return WorldSpec(self.gravity, self.floor, tuple(f.spec() for f in self.fixtures),
                         tuple(t.spec(i) for i, t in enumerate(self.tools)),
                         tuple(p.spec() for p in self.parts), tuple(z.spec() for z in self.zones),
                         self.lock_distance, self.lock_angle_deg * _DEG)


class IoUnitTable(Table):
    id: integer(0, 32767)
    name: Name
    direction: string(("input", "output"))


class IoSignalTable(Table):
    name: Name
    unit: integer()
    bit: integer(0, MAX_BITS - 1)
    wire: Name | None = None   # default: its name if that is a wire, else "none"

    def wired(self) -> str:
        if self.wire is not None:
            return self.wire
        return self.name if self.name in INPUT_WIRES + OUTPUT_WIRES else "none"


class IoTable(Table):
    units: list[IoUnitTable] = []
    signals: list[IoSignalTable] = []

    @model_validator(mode="after")
    def _consistent(self):
        ids = [u.id for u in self.units]
        if len(set(ids)) != len(ids):
            raise problem("two units share an id", "units")
        names(self.units, "units", "units")
        for i, s in enumerate(self.signals):
            if s.unit not in ids:
                raise problem(f"expected the id of a unit ({', '.join(map(str, sorted(ids)))}), "
                              f"got {s.unit}", f"signals[{i}].unit")
        names(self.signals, "signals", "signals")
        slots = [(s.unit, s.bit) for s in self.signals]
        for unit, bit in slots:
            if slots.count((unit, bit)) > 1:
                raise problem(f"unit {unit} bit {bit} is used twice", "signals")
        driven = [s.wired() for s in self.signals
                  if self._direction(s) == "output" and s.wired() != "none"]
        for wire in driven:
            if driven.count(wire) > 1:
                raise problem(f"two outputs drive {wire!r}", "signals")
        return self

    def _direction(self, signal: IoSignalTable) -> str:
        return next(u.direction for u in self.units if u.id == signal.unit)

    def check_wires(self, zones: set[str]) -> None:
        """Each signal's wire among those of its direction (inputs: zones of the world too)."""
        tool_ids = {f"tool_id:{b}" for b in range(MAX_TOOL_ID_BITS)}
        for i, s in enumerate(self.signals):
            wire = s.wired()
            if self._direction(s) == "input":
                if not (wire in INPUT_WIRES or wire in tool_ids
                        or (wire.startswith("zone:") and wire[5:] in zones)):
                    raise problem(
                        f"expected an input wire: one of {', '.join(INPUT_WIRES)}, zone:<name> "
                        f"(zones: {', '.join(sorted(zones)) or 'none'}) or tool_id:<bit> "
                        f"(0..{MAX_TOOL_ID_BITS - 1}); got {wire!r}", f"io.signals[{i}].wire")
            elif wire not in OUTPUT_WIRES:
                raise problem(f"expected an output wire: one of {', '.join(OUTPUT_WIRES)}; "
                              f"got {wire!r}", f"io.signals[{i}].wire")

    def spec(self) -> IoSpec:
        return IoSpec(tuple(IoUnitSpec(u.id, u.name, u.direction) for u in self.units),
                      tuple(IoSignalSpec(s.name, s.unit, s.bit, s.wired(), self._direction(s))
                            for s in self.signals))


class SensorTable(Table):
    kind: string(SENSOR_KINDS)
    # A laser_range's:
    max_range: Positive = SensorSpec.max_range
    min_range: number(low=0.0) = SensorSpec.min_range
    offset: Vector3 = SensorSpec.offset

    @model_validator(mode="after")
    def _keys_of_its_kind(self):
        for key in ("max_range", "min_range", "offset"):
            if self.given(key) and self.kind != "laser_range":
                raise problem(f"only a laser_range has a {key} (this sensor is a {self.kind})",
                              key)
        if self.min_range >= self.max_range:
            raise problem(f"expected a number below max_range ({self.max_range:g}), "
                          f"got {self.min_range:g}", "min_range")
        return self

    def spec(self, name: str) -> SensorSpec:
        return SensorSpec(name, self.kind, self.max_range, self.min_range, self.offset)


class RecorderTable(Table):
    path: Name = RecorderSpec.path
    frequency_percent: number(0.01, 100.0) = RecorderSpec.frequency_percent
    max_seconds: Positive = RecorderSpec.max_seconds


class CellFile(Table):
    """The whole file."""

    name: Name = "cell"
    arm: ArmTable = ArmTable()
    controller: ControllerTable = ControllerTable()
    world: WorldTable = WorldTable()
    io: IoTable = IoTable()
    sensors: dict[str, SensorTable] = {}
    recorder: RecorderTable = RecorderTable()

    @model_validator(mode="after")
    def _tables_agree(self):
        arm = self.arm.arm_model()
        q = _radians(self.controller.initial_position_deg)
        for i, (v, lo, hi) in enumerate(zip(q, arm.joint_min, arm.joint_max)):
            if not lo <= v <= hi:
                raise problem(f"joint {i + 1} at {v / _DEG:.3f} deg is outside its range "
                              f"[{lo / _DEG:.3f}, {hi / _DEG:.3f}] deg",
                              "controller.initial_position_deg")
        self.io.check_wires({z.name for z in self.world.zones})
        return self

    def cell(self, source: str) -> Cell:
        return Cell(name=self.name, arm=self.arm.arm_model(),
                    base=Pose(self.arm.base_xyz, _radians(self.arm.base_rpy_deg)),
                    controller=self.controller.spec(), world=self.world.spec(),
                    io=self.io.spec(),
                    sensors=tuple(s.spec(name) for name, s in self.sensors.items()),
                    recorder=RecorderSpec(self.recorder.path, self.recorder.frequency_percent,
                                          self.recorder.max_seconds),
                    source=source)


# ---- entry points -----------------------------------------------------------------------------

def parse_cell(text: str, source: str = "<string>") -> Cell:
    """A cell from TOML text; raises CellError naming `source` and the bad key."""
    return read_toml(text, CellFile, source, CellError).cell(source)


def load_cell(path: str | Path | None = None) -> Cell:
    """The cell in the TOML file at `path`; None: the default cell shipped with the package."""
    if path is None:
        ref = resources.files("landscape.robot").joinpath("cells/default.toml")
        return parse_cell(ref.read_text(encoding="utf-8"), "cells/default.toml")
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise CellError(f"{path}: cannot read the cell file: {exc.strerror}") from None
    return parse_cell(text, str(path))
