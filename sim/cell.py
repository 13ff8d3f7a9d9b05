"""The cell file: one TOML file configuring a simulated cell, parsed into frozen dataclasses
(cell_model.py, all of them named here too).

Like the CS8's configuration files together (controller.cfx for the cycle time, cell.cf for the
named I/O, records.cfx for the recorder), plus what a simulator needs: the arm variant, the world
(floor, fixtures, tools, parts, zones) and the sensors. `sim/cells/default.toml` is the
reference, with every key commented.

Units: metres, kilograms, seconds, newtons; angles in degrees where the key ends in `_deg`,
radians everywhere else (so arm overrides such as `max_acceleration` are rad/s^2, as in
`ArmModel`). Poses are `xyz` (m) plus `rpy_deg`, fixed-axis X-Y-Z (R = Rz(yaw) Ry(pitch) Rx(roll),
DESIGN.md section 6), in the world frame unless said otherwise. Unknown keys are errors, so a
typo never silently falls back to a default; every error names the file and the key.
"""
from __future__ import annotations

import dataclasses
import math
import tomllib
from importlib import resources
from pathlib import Path
from typing import Any

from landscape.sim.arm import ArmModel, arm_model
from landscape.sim.cell_model import (  # noqa: F401  (the parsed cell, named here too)
    BoxSpec, Cell, ControllerSpec, INPUT_WIRES, IoSignalSpec, IoSpec, IoUnitSpec, MAX_BITS,
    MAX_TOOL_ID_BITS, OUTPUT_WIRES, PANEL_WIRES, Pose, RecorderSpec, SENSOR_KINDS, SensorSpec,
    TOOL_KINDS, ToolSpec, WORLD_INPUT_WIRES, WorldSpec, ZoneSpec)
from landscape.sim.cycle_process import check_cycle_time

_DEG = math.pi / 180.0
_MISSING = object()


class CellError(ValueError):
    """A cell file that cannot be used; the message names the file and the key."""


# ---- reading ----------------------------------------------------------------------------------

class _Table:
    """A TOML table being read: typed getters that name the key in errors, and a check that
    every key was used."""

    def __init__(self, data: Any, where: str, source: str):
        self.source, self.where = source, where
        if not isinstance(data, dict):
            self.fail("", "must be a table")
        self.data = data
        self.used: set[str] = set()

    def fail(self, key: str, message: str):
        name = f"{self.where}.{key}" if self.where and key else (self.where or key)
        raise CellError(f"{self.source}: {name or '(top level)'}: {message}")

    def has(self, key: str) -> bool:
        return key in self.data

    def raw(self, key: str, default=_MISSING):
        self.used.add(key)
        if key in self.data:
            return self.data[key]
        if default is _MISSING:
            self.fail(key, "is required")
        return default

    def number(self, key, default=_MISSING, *, low=None, high=None, positive=False) -> float:
        v = self.raw(key, default)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v):
            self.fail(key, f"must be a finite number, got {v!r}")
        if positive and v <= 0:
            self.fail(key, f"must be positive, got {v!r}")
        if (low is not None and v < low) or (high is not None and v > high):
            self.fail(key, f"must be within [{low}, {high}], got {v!r}")
        return float(v)

    def integer(self, key, default=_MISSING, *, low=None, high=None) -> int:
        v = self.raw(key, default)
        if isinstance(v, bool) or not isinstance(v, int):
            self.fail(key, f"must be an integer, got {v!r}")
        if (low is not None and v < low) or (high is not None and v > high):
            self.fail(key, f"must be within [{low}, {high}], got {v!r}")
        return v

    def string(self, key, default=_MISSING, choices=None) -> str:
        v = self.raw(key, default)
        if not isinstance(v, str) or not v:
            self.fail(key, f"must be a non-empty string, got {v!r}")
        if choices is not None and v not in choices:
            self.fail(key, f"must be one of {', '.join(choices)}; got {v!r}")
        return v

    def boolean(self, key, default=_MISSING) -> bool:
        v = self.raw(key, default)
        if not isinstance(v, bool):
            self.fail(key, f"must be true or false, got {v!r}")
        return v

    def vector(self, key, n, default=_MISSING, *, scale=1.0, positive=False) -> tuple:
        v = self.raw(key, default)
        if (not isinstance(v, (list, tuple)) or len(v) != n
                or any(isinstance(x, bool) or not isinstance(x, (int, float))
                       or not math.isfinite(x) for x in v)):
            self.fail(key, f"must be a list of {n} finite numbers, got {v!r}")
        if positive and min(v) <= 0:
            self.fail(key, f"must hold positive numbers, got {v!r}")
        return tuple(float(x) * scale for x in v)

    def table(self, key) -> "_Table":
        return _Table(self.raw(key, {}), f"{self.where}.{key}" if self.where else key, self.source)

    def tables(self, key) -> list["_Table"]:
        items = self.raw(key, [])
        if not isinstance(items, list):
            self.fail(key, "must be an array of tables ([[...]])")
        where = f"{self.where}.{key}" if self.where else key
        return [_Table(item, f"{where}[{i}]", self.source) for i, item in enumerate(items)]

    def pose(self, xyz_key="xyz", rpy_key="rpy_deg", xyz_default=_MISSING) -> Pose:
        return Pose(self.vector(xyz_key, 3, xyz_default),
                    self.vector(rpy_key, 3, (0.0, 0.0, 0.0), scale=_DEG))

    def done(self) -> None:
        unknown = sorted(set(self.data) - self.used)
        if unknown:
            self.fail(unknown[0], f"unknown key (known here: {', '.join(sorted(self.used))})")


def _unique(items, what: str, table: _Table, key: str) -> None:
    names = [i.name for i in items]
    for name in names:
        if names.count(name) > 1:
            table.fail(key, f"two {what} are named {name!r}")


# ---- sections ---------------------------------------------------------------------------------

_ARM_JOINT_LIMITS = ("max_velocity", "max_acceleration", "max_effort")   # (6,) each
# The arm's scalar limits (Cartesian speeds and accelerations of the tool tip, SI units).
_ARM_SCALAR_LIMITS = tuple(f.name for f in dataclasses.fields(ArmModel)
                           if f.name.startswith("max_") and f.type in ("float", float))


def _arm(t: _Table) -> tuple[ArmModel, Pose]:
    variant = t.string("variant", "TX90")
    overrides: dict[str, Any] = {key: t.vector(key, 6, positive=True)
                                 for key in _ARM_JOINT_LIMITS if t.has(key)}
    overrides.update((key, t.number(key, positive=True))
                     for key in _ARM_SCALAR_LIMITS if t.has(key))
    for key in ("joint_min", "joint_max"):
        if t.has(f"{key}_deg"):
            overrides[key] = t.vector(f"{key}_deg", 6, scale=_DEG)
    base = t.pose("base_xyz", "base_rpy_deg", (0.0, 0.0, 0.0))
    t.done()
    try:
        return arm_model(variant, **overrides), base
    except ValueError as exc:
        t.fail("variant" if "variant" in str(exc) else "", str(exc))


def _in_range(t: _Table, key: str, q: tuple, arm: ArmModel) -> None:
    for i, (v, lo, hi) in enumerate(zip(q, arm.joint_min, arm.joint_max)):
        if not lo <= v <= hi:
            t.fail(key, f"joint {i + 1} at {v / _DEG:.3f} deg is outside its range "
                        f"[{lo / _DEG:.3f}, {hi / _DEG:.3f}] deg")


def _controller(t: _Table, arm: ArmModel) -> ControllerSpec:
    d = ControllerSpec()
    cycle = t.number("cycle_time", d.cycle_time, positive=True)
    try:
        check_cycle_time(cycle)
    except ValueError as exc:
        t.fail("cycle_time", str(exc))
    spec = ControllerSpec(
        cycle_time=cycle,
        physics_step=t.number("physics_step", d.physics_step, positive=True),
        enable_time=t.number("enable_time", d.enable_time, low=0.0, high=10.0),
        disable_time=t.number("disable_time", d.disable_time, low=0.0, high=10.0),
        acceleration_factor=t.number("acceleration_factor", d.acceleration_factor, low=1.0),
        effort_factor=t.number("effort_factor", d.effort_factor, positive=True),
        brake_factor=t.number("brake_factor", d.brake_factor, positive=True),
        initial_position=t.vector("initial_position_deg", 6,
                                  tuple(v / _DEG for v in d.initial_position), scale=_DEG),
        user_marks=t.vector("user_marks_deg", 6, (0.0,) * 6, scale=_DEG),
    )
    _in_range(t, "initial_position_deg", spec.initial_position, arm)
    t.done()
    return spec


def _box(t: _Table, *, part: bool) -> BoxSpec:
    spec = BoxSpec(
        name=t.string("name"),
        pose=t.pose(),
        size=t.vector("size", 3, positive=True),
        mass=t.number("mass", _MISSING if part else 0.0, positive=part, low=0.0),
        color=t.vector("color", 4, (0.8, 0.3, 0.2, 1.0) if part else (0.6, 0.6, 0.6, 1.0)),
    )
    t.done()
    return spec


def _tool(t: _Table, index: int) -> ToolSpec:
    d = ToolSpec("", "", Pose(), 0.0, 0.0)
    kind = t.string("kind", choices=TOOL_KINDS)
    spec = ToolSpec(
        name=t.string("name"), kind=kind, slot=t.pose(),
        mass=t.number("mass", positive=True), length=t.number("length", positive=True),
        id=t.integer("id", index + 1, low=1, high=2 ** MAX_TOOL_ID_BITS - 1),
        stroke=t.number("stroke", d.stroke, positive=True) if kind == "parallel_gripper"
        else d.stroke,
        finger_speed=t.number("finger_speed", d.finger_speed, positive=True)
        if kind == "parallel_gripper" else d.finger_speed,
        cup_radius=t.number("cup_radius", d.cup_radius, positive=True) if kind == "vacuum_cup"
        else d.cup_radius,
        contact_stiffness=t.number("contact_stiffness", d.contact_stiffness, positive=True),
        contact_damping=t.number("contact_damping", d.contact_damping, positive=True),
    )
    t.done()
    return spec


def _zone(t: _Table) -> ZoneSpec:
    spec = ZoneSpec(t.string("name"), t.vector("xyz", 3), t.vector("size", 3, positive=True))
    t.done()
    return spec


def _world(t: _Table) -> WorldSpec:
    d = WorldSpec()
    fixtures = tuple(_box(x, part=False) for x in t.tables("fixtures"))
    tools = tuple(_tool(x, i) for i, x in enumerate(t.tables("tools")))
    parts = tuple(_box(x, part=True) for x in t.tables("parts"))
    zones = tuple(_zone(x) for x in t.tables("zones"))
    spec = WorldSpec(
        gravity=t.vector("gravity", 3, d.gravity), floor=t.boolean("floor", d.floor),
        fixtures=fixtures, tools=tools, parts=parts, zones=zones,
        lock_distance=t.number("lock_distance", d.lock_distance, positive=True),
        lock_angle=t.number("lock_angle_deg", d.lock_angle / _DEG, positive=True) * _DEG,
    )
    _unique(fixtures + parts, "fixtures or parts", t, "parts")
    _unique(tools, "tools", t, "tools")
    ids = [tool.id for tool in tools]
    if len(set(ids)) != len(ids):
        t.fail("tools", "two tools share an id")
    _unique(zones, "zones", t, "zones")
    t.done()
    return spec


def _io(t: _Table, world: WorldSpec) -> IoSpec:
    units = []
    for u in t.tables("units"):
        units.append(IoUnitSpec(u.integer("id", low=0, high=32767), u.string("name"),
                                u.string("direction", choices=("input", "output"))))
        u.done()
    ids = [u.id for u in units]
    if len(set(ids)) != len(ids):
        t.fail("units", "two units share an id")
    _unique(units, "units", t, "units")
    direction = {u.id: u.direction for u in units}
    zones = {z.name for z in world.zones}
    signals = []
    for s in t.tables("signals"):
        name = s.string("name")
        unit = s.integer("unit")
        if unit not in direction:
            s.fail("unit", f"no unit has id {unit} (units: {sorted(direction)})")
        bit = s.integer("bit", low=0, high=MAX_BITS - 1)
        wire = s.string("wire", name if name in INPUT_WIRES + OUTPUT_WIRES else "none")
        if direction[unit] == "input":
            ok = (wire in INPUT_WIRES or (wire.startswith("zone:") and wire[5:] in zones)
                  or wire in {f"tool_id:{b}" for b in range(MAX_TOOL_ID_BITS)})
            if not ok:
                s.fail("wire", f"an input wire is one of {', '.join(INPUT_WIRES)}, zone:<name> "
                               f"(zones: {', '.join(sorted(zones)) or 'none'}) or tool_id:<bit> "
                               f"(0..{MAX_TOOL_ID_BITS - 1}); got {wire!r}")
        elif wire not in OUTPUT_WIRES:
            s.fail("wire", f"an output wire is one of {', '.join(OUTPUT_WIRES)}; got {wire!r}")
        signals.append(IoSignalSpec(name, unit, bit, wire, direction[unit]))
        s.done()
    _unique(signals, "signals", t, "signals")
    slots = [(s.unit, s.bit) for s in signals]
    for s in signals:
        if slots.count((s.unit, s.bit)) > 1:
            t.fail("signals", f"unit {s.unit} bit {s.bit} is used twice")
    wires = [s.wire for s in signals if s.direction == "output" and s.wire != "none"]
    for w in wires:
        if wires.count(w) > 1:
            t.fail("signals", f"two outputs drive {w!r}")
    t.done()
    return IoSpec(tuple(units), tuple(signals))


def _sensors(t: _Table) -> tuple[SensorSpec, ...]:
    out = []
    for name in list(t.data):
        s = t.table(name)
        kind = s.string("kind", choices=SENSOR_KINDS)
        if kind == "laser_range":
            d = SensorSpec(name, kind)
            spec = SensorSpec(name, kind,
                              max_range=s.number("max_range", d.max_range, positive=True),
                              min_range=s.number("min_range", d.min_range, low=0.0),
                              offset=s.vector("offset", 3, d.offset))
            if spec.min_range >= spec.max_range:
                s.fail("min_range", "must be below max_range")
        else:
            spec = SensorSpec(name, kind)
        s.done()
        out.append(spec)
    return tuple(out)


def _recorder(t: _Table) -> RecorderSpec:
    d = RecorderSpec()
    spec = RecorderSpec(t.string("path", d.path),
                        t.number("frequency_percent", d.frequency_percent, low=0.01, high=100.0),
                        t.number("max_seconds", d.max_seconds, positive=True))
    t.done()
    return spec


# ---- entry points -----------------------------------------------------------------------------

def parse_cell(text: str, source: str = "<string>") -> Cell:
    """A cell from TOML text; raises CellError naming `source` and the bad key."""
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise CellError(f"{source}: not valid TOML: {exc}") from None
    top = _Table(data, "", source)
    arm, base = _arm(top.table("arm"))
    world = _world(top.table("world"))
    cell = Cell(
        name=top.string("name", "cell"),
        arm=arm, base=base,
        controller=_controller(top.table("controller"), arm),
        world=world,
        io=_io(top.table("io"), world),
        sensors=_sensors(top.table("sensors")),
        recorder=_recorder(top.table("recorder")),
        source=source,
    )
    top.done()
    return cell


def load_cell(path: str | Path | None = None) -> Cell:
    """The cell in the TOML file at `path`; None: the default cell shipped with the package."""
    if path is None:
        ref = resources.files("landscape.sim").joinpath("cells/default.toml")
        return parse_cell(ref.read_text(encoding="utf-8"), "cells/default.toml")
    path = Path(path)
    try:
        text = path.read_text(encoding="utf-8")
    except OSError as exc:
        raise CellError(f"{path}: cannot read the cell file: {exc.strerror}") from None
    return parse_cell(text, str(path))
