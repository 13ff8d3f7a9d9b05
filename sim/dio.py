"""Digital I/O of the cell: named bits grouped in units, as the CS8's cell.cf declares them.

LandScape's setDigitalIO/getDigitalIO address a unit by id and its bits by a bit field (bit i is
`1 << i`); the LLI addresses one signal by name. `DigitalIO` offers both. Outputs hold their
value and tell `on_output` when a wired one changes; inputs are read on demand from `read_input`
(the world and the panel), so nothing is computed per cycle unless someone reads.

`EdgeDetector` turns successive reads of a unit into "bits that rose / fell" for events.
Not thread-safe: call from the thread that steps the controller.
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Callable

from landscape.robot.cell import IoSpec


@dataclass(frozen=True)
class Signal:
    """One named bit: unit id, bit index (0..31), direction "input" or "output", and its wire."""

    name: str
    unit: int
    bit: int
    direction: str
    wire: str

    @property
    def mask(self) -> int:
        return 1 << self.bit


class DigitalIO:
    """The cell's digital I/O.

    read_input(wire) -> bool gives the present value of an input's wire; on_output(wire, value)
    is called when an output with a wire other than "none" changes.
    """

    def __init__(self, spec: IoSpec, read_input: Callable[[str], bool],
                 on_output: Callable[[str, bool], None]):
        self.units = {u.id: u for u in spec.units}
        self.signals = {s.name: Signal(s.name, s.unit, s.bit, s.direction, s.wire)
                        for s in spec.signals}
        self._by_unit: dict[int, list[Signal]] = {u: [] for u in self.units}
        for s in self.signals.values():
            self._by_unit[s.unit].append(s)
        self._read_input, self._on_output = read_input, on_output
        self._outputs = {u.id: 0 for u in spec.units if u.direction == "output"}
        # Per input unit, its wired bits as (mask, wire): what a read of the unit looks at
        # (the cycle reads its I/O image every cycle).
        self._wired = {u: [(s.mask, s.wire) for s in signals if s.wire != "none"]
                       for u, signals in self._by_unit.items() if u not in self._outputs}

    # ---- by name ------------------------------------------------------------------------------

    def lookup(self, name: str) -> Signal | None:
        return self.signals.get(name)

    def _signal(self, name: str) -> Signal:
        try:
            return self.signals[name]
        except KeyError:
            raise KeyError(f"no digital I/O named {name!r}") from None

    def read(self, name: str) -> bool:
        s = self._signal(name)
        if s.direction == "output":
            return bool(self._outputs[s.unit] & s.mask)
        return s.wire != "none" and bool(self._read_input(s.wire))

    def write(self, name: str, value: bool) -> None:
        s = self._signal(name)
        if s.direction != "output":
            raise ValueError(f"{name!r} is an input: it cannot be written")
        self.write_unit(s.unit, s.mask if value else 0, 0 if value else s.mask)

    # ---- by unit and bit field ----------------------------------------------------------------

    def read_unit(self, unit: int, mask: int = -1) -> int:
        """The unit's bits as an int: bit i set when the signal at bit i is 1. Only the bits of
        `mask` are read (the others read 0): some inputs cost a look at the world."""
        if unit in self._outputs:
            return self._outputs[unit] & mask
        wired = self._wired.get(unit)
        if wired is None:
            raise KeyError(f"no I/O unit {unit} (units: {sorted(self.units)})")
        bits, read = 0, self._read_input
        for bit, wire in wired:
            if bit & mask and read(wire):
                bits |= bit
        return bits

    def write_unit(self, unit: int, bits_on: int = 0, bits_off: int = 0) -> None:
        """Set the bits of `bits_on` and clear those of `bits_off` of an output unit. Every bit
        named must be a declared output; a bit in both fields is an error. Wired outputs that
        change are passed on, lowest bit first."""
        if unit not in self.units:
            raise KeyError(f"no I/O unit {unit} (units: {sorted(self.units)})")
        if unit not in self._outputs:
            raise ValueError(f"I/O unit {unit} ({self.units[unit].name}) holds inputs: "
                             "it cannot be written")
        if bits_on & bits_off:
            raise ValueError(f"bits {bits_on & bits_off:#x} are both set and cleared")
        declared = 0
        for s in self._by_unit[unit]:
            declared |= s.mask
        stray = (bits_on | bits_off) & ~declared
        if stray or bits_on < 0 or bits_off < 0:
            raise ValueError(f"I/O unit {unit} has no outputs at bits {stray:#x}")
        old = self._outputs[unit]
        new = (old | bits_on) & ~bits_off
        self._outputs[unit] = new
        for s in sorted(self._by_unit[unit], key=lambda s: s.bit):
            if (old ^ new) & s.mask and s.wire != "none":
                self._on_output(s.wire, bool(new & s.mask))

    def snapshot(self) -> dict[int, int]:
        """Every unit's bits, by unit id."""
        return {u: self.read_unit(u) for u in self.units}


class EdgeDetector:
    """Bits that changed between successive samples of a bit field (one unit)."""

    def __init__(self, bits: int = 0):
        self.bits = bits

    def update(self, bits: int) -> tuple[int, int]:
        """Take a new sample; return (rising, falling): the bits that went 0->1 and 1->0."""
        changed = bits ^ self.bits
        self.bits = bits
        return changed & bits, changed & ~bits
