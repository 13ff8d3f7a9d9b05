"""The set commands' settings (seed 3.2) as stored beside the paths, and back.

Tool offset, world frame, units, speeds and accelerations survive a restart of the device
server: every accepted change is written in the same SQLite file as the paths, in one
transaction, before it takes effect. Read back, each value goes through the same validation
as a Set command; a stored value that no longer passes (an arm with other limits) is dropped
with a warning and its default kept. `landscape-device-server --reset-settings` starts from
the defaults (and stores them).
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
    if `reset`, stored at once), and each change validated, stored, then in force. One change
    at a time, under a lock of its own (the file may keep it waiting)."""

    def __init__(self, defaults: MotionSettings, store: PathStore, reset: bool = False):
        self._store = store
        self._current = defaults if reset else from_record(defaults, store.load_settings())
        if reset:
            with contextlib.suppress(CommandError):   # reported by the store; in force anyway
                store.save_settings(to_record(defaults))
        self._lock = threading.Lock()

    @property
    def current(self) -> MotionSettings:
        return self._current

    def update(self, change: Callable[[MotionSettings], MotionSettings]) -> MotionSettings:
        """Apply `change(settings) -> settings`: validated, stored, then in force; a validation
        or storage error leaves them as they were."""
        with self._lock:
            settings = change(self._current)
            self._store.save_settings(to_record(settings))
            self._current = settings
            return settings
