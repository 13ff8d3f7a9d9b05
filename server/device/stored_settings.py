"""The set commands' settings (seed 3.2) as stored beside the paths, and back.

Tool offset, world frame, units, speeds and accelerations survive a restart of the device
server: an accepted change is in force at once and written behind, in the same SQLite file as
the paths, within WRITE_BEHIND seconds (the changes of that interval in one transaction, the
newest settings whole); stopping the server (SIGTERM, SIGINT, SIGHUP) writes what is pending
at once. A server killed outright (SIGKILL, a power cut) within that interval after a change
comes back with the settings stored before it (docs/performance.md says so too). While the
file cannot be written (a full disk: its last write failed), each change is written through
before it takes effect, and refused if that fails, as the paths are. Read back, each value
goes through the same validation as a Set command; a stored value that no longer passes (an
arm with other limits) is dropped with a warning and its default kept.
`landscape-device-server --reset-settings` starts from the defaults (and stores them).
"""
from __future__ import annotations

import contextlib
import logging
import threading
from typing import Callable

import numpy as np

from landscape.robot.units import AngularUnit, LinearUnit, Units
from landscape.server.device.motion_settings import Kind, MotionSettings
from landscape.server.errors import CommandError
from landscape.server.planning.paths import PathStore

log = logging.getLogger(__name__)

# s: the longest an accepted change waits to be written (it is in force at once). Short
# enough that a restart finds it; long enough that a burst (a CRCL program sets a speed, an
# acceleration and a tool offset per move) is one transaction.
WRITE_BEHIND = 0.2


def to_record(settings: MotionSettings) -> dict:
    return {"speed_percent": settings.speed_percent, "accel_percent": settings.accel_percent,
            "linear_speed": settings.linear_speed, "angular_speed": settings.angular_speed,
            "linear_accel": settings.linear_accel, "angular_accel": settings.angular_accel,
            "tool_offset": np.asarray(settings.tool_offset).ravel().tolist(),
            "world_frame": np.asarray(settings.world_frame).ravel().tolist(),
            "units": [settings.units.linear.name, settings.units.angular.name]}


# How each stored value is applied: the Set command's own validation.
_APPLY = {
    "speed_percent": lambda s, v: s.with_speed(Kind.PERCENT, v),
    "accel_percent": lambda s, v: s.with_accel(Kind.PERCENT, v),
    "linear_speed": lambda s, v: s.with_speed(Kind.LINEAR, v),
    "angular_speed": lambda s, v: s.with_speed(Kind.ANGULAR, v),
    "linear_accel": lambda s, v: s.with_accel(Kind.LINEAR, v),
    "angular_accel": lambda s, v: s.with_accel(Kind.ANGULAR, v),
    "tool_offset": lambda s, v: s.with_tool_offset(np.reshape(v, (4, 4))),
    "world_frame": lambda s, v: s.with_world_frame(np.reshape(v, (4, 4))),
    "units": lambda s, v: s.with_units(Units(LinearUnit[v[0]], AngularUnit[v[1]])),
}


def from_record(defaults: MotionSettings, record: dict | None) -> MotionSettings:
    settings = defaults
    for key, value in (record or {}).items():
        apply = _APPLY.get(key)
        if apply is None:
            log.warning("stored setting %r is unknown; ignored", key)
            continue
        try:
            settings = apply(settings, value)
        except (CommandError, KeyError, TypeError, ValueError) as error:
            log.warning("stored setting %s=%r does not apply (%s); the default stays",
                        key, value, error)
    return settings


class SettingsKeeper:
    """The settings in force, kept in `store` (a PathStore): read back at start (the defaults
    if `reset`, stored at once); each change validated and in force at once, then written
    behind by a thread of its own within `delay` seconds (0: before `update` returns;
    `close` writes what is pending).
    Changes take a lock of their own, never held while the file is written, except while the
    file fails: then each change is written through, and refused if it cannot be."""

    def __init__(self, defaults: MotionSettings, store: PathStore, reset: bool = False,
                 delay: float = WRITE_BEHIND):
        self._store, self._delay = store, delay
        self._current = defaults if reset else from_record(defaults, store.load_settings())
        self._written = self._current           # the settings the file holds
        if reset:
            with contextlib.suppress(CommandError):   # reported by the store; in force anyway
                store.save_settings(to_record(defaults))
        self._lock = threading.Lock()           # one change at a time
        self._writing = threading.Lock()        # one write at a time, in order
        self._due = threading.Event()           # a change waits to be written
        self._closing = threading.Event()
        self._writer = threading.Thread(target=self._write_behind, name="settings-writer",
                                        daemon=True)
        self._writer.start()

    @property
    def current(self) -> MotionSettings:
        return self._current

    @property
    def writes_through(self) -> bool:
        """Whether `update` writes to the file before it returns (a delay of 0, a file that
        fails, a keeper closing)."""
        return self._delay == 0 or self._store.failing or self._closing.is_set()

    def update(self, change: Callable[[MotionSettings], MotionSettings]) -> MotionSettings:
        """Apply `change(settings) -> settings`: validated, in force, written behind; a
        validation error (or, while the file fails, a storage error) leaves them as they
        were."""
        with self._lock:
            settings = change(self._current)
            if self.writes_through:
                with self._writing:
                    self._store.save_settings(to_record(settings))
                    self._written = settings
            self._current = settings
        self._due.set()
        return settings

    def flush(self) -> None:
        """Write the settings in force now, if the file does not hold them yet. A failure is
        the store's to report (an alarm); the writer tries again after its delay."""
        with self._writing:
            settings = self._current
            if settings is self._written:
                return
            try:
                self._store.save_settings(to_record(settings))
            except CommandError:
                self._due.set()
                return
            self._written = settings

    def close(self) -> None:
        """Write what is pending, now; later changes are written through."""
        self._closing.set()
        self._due.set()
        self._writer.join(5.0)
        self.flush()

    def _write_behind(self) -> None:
        while not self._closing.is_set():
            self._due.wait()
            self._closing.wait(self._delay)     # the changes of the next `delay` s, together
            self._due.clear()
            self.flush()
