"""Manual control and jogging (seed 3.7.3 manualControl, and the Jog stream).

manualControl("teachpendant" | "spaceball") hands the arm to a manual device: from then on only
Jog moves it (every other motion command is refused until manualControl("off")); both types
allow the same jogging. The mode ends with the lock (release, or the lock holder lost).

A Jog stream is one jog session, a motion of its own (command "Jog": started, then done when
the client ends the stream, aborted by StopMotion, AbortMotion, the deadman or the lock holder
going, failed when the drives go off); the device is Moving meanwhile, so nothing else moves
the arm. Each request gives velocities in percent, -100 to 100, of the axis's jog speed:
a joint's maximum velocity, or the arm's linear and angular tool speeds, times the set speed
(SetSpeed). The cycle integrates them within the joint ranges, the acceleration limits and
the manual-mode tip speed, with the deadman (jog_integrator.py): no request for the deadman
timeout (default DEADMAN_TIMEOUT, from the stream's first request) stops the arm at its full
deceleration and ends the session; releasing the deadman holds the arm until it is pressed.
Near the cell the arm slows and stops at the collision margin (jog_guard.py); the stream's
replies say so.
"""
from __future__ import annotations

import math

import numpy as np

from landscape.robot.arm import ArmModel
from landscape.server.cycle.jog_integrator import MANUAL_TIP_SPEED, JogLimits
from landscape.server.device.motion_control import ENDED, MotionControl, RunningMotion
from landscape.server.device.state_machine import MANUAL_OFF, StateMachine
from landscape.server.device.stored_settings import SettingsKeeper
from landscape.server.errors import ManualControlMode, OutOfRange, ParamError
from landscape.server.link.controller_link import ControllerLink
from landscape.server.planning.collision import CollisionScene
from landscape.server.planning.targets import Frame
from landscape.server.workcell.jog_guard import JogGuard

MODES = ("teachpendant", "spaceball", "off")
DEADMAN_TIMEOUT = 0.2          # s
DEADMAN_RANGE = (0.02, 1.0)    # s: the timeouts a client may choose


class ManualControl:
    def __init__(self, state: StateMachine, motions: MotionControl, link: ControllerLink,
                 collisions: CollisionScene, settings: SettingsKeeper, arm: ArmModel):
        self.state, self.motions, self.link = state, motions, link
        self.collisions, self.settings, self.arm = collisions, settings, arm

    def set_mode(self, mode: str) -> None:
        if mode not in MODES:
            raise ParamError(f"manual control is one of {', '.join(MODES)}, got {mode!r}")
        self.state.set_manual_control(mode)

    def start(self, deadman_timeout: float | None) -> "JogSession":
        """A jog session from rest; the deadman timeout (s) or the default."""
        if self.state.manual_control == MANUAL_OFF:
            raise ManualControlMode("jogging needs manual control: ManualControl(teachpendant "
                                    "or spaceball) first")
        timeout = DEADMAN_TIMEOUT if not deadman_timeout else deadman_timeout
        if not DEADMAN_RANGE[0] <= timeout <= DEADMAN_RANGE[1]:
            raise OutOfRange(f"the deadman timeout must be {DEADMAN_RANGE[0] * 1000:g} to "
                             f"{DEADMAN_RANGE[1] * 1000:g} ms")
        settings, arm = self.settings.current, self.arm
        cartesian = np.array([arm.max_linear_acceleration, arm.max_angular_acceleration])
        limits = JogLimits(settings.joint_velocities, settings.joint_accelerations,
                           np.asarray(arm.max_acceleration), arm.lower, arm.upper,
                           cartesian * settings.accel_percent / 100.0, cartesian,
                           MANUAL_TIP_SPEED, math.ceil(timeout / self.link.cycle_time),
                           settings.joint_jerks, np.asarray(arm.max_jerk))
        motion = self.motions.start_jog({"limits": limits, "tool_offset": settings.tool_offset,
                                           "guarded": True})   # JogSession starts the guard
        guard = JogGuard(self.link, self.motions, self.collisions, motion)
        return JogSession(self.motions, self.settings, motion, guard)


class JogSession:
    def __init__(self, motions: MotionControl, settings: SettingsKeeper, motion: RunningMotion,
                 guard: JogGuard):
        self.motions, self.settings, self.motion, self.guard = motions, settings, motion, guard

    @property
    def ended(self) -> bool:
        return self.motion.phase in ENDED

    @property
    def status(self) -> str:
        """What the Jog stream's replies say: jogging, or what holds the arm where it is."""
        return f"jogging; {self.guard.held}" if self.guard.held else "jogging"

    def request(self, frame: Frame, percent: np.ndarray, deadman: bool) -> None:
        """One jog request: velocities in percent per axis (joints, or vx, vy, vz, wx, wy, wz of
        the tip in `frame`)."""
        percent = np.asarray(percent, dtype=float)
        if percent.shape != (6,) or not np.all(np.isfinite(percent)):
            raise ParamError("a jog request needs 6 finite velocities (percent)")
        if np.any(np.abs(percent) > 100.0):
            raise OutOfRange("jog velocities are -100 to 100 % of the axis's jog speed")
        settings = self.settings.current
        if frame is Frame.JOINT:
            velocity = percent / 100.0 * settings.joint_velocities
        else:
            scale = settings.speed_percent / 100.0 / 100.0
            velocity = percent * scale * np.repeat([settings.linear_speed,
                                                    settings.angular_speed], 3)
        self.motions.send({"op": "jog_velocity", "frame": frame.value,
                                  "velocity": velocity, "deadman": bool(deadman),
                                  "world_rotation": settings.world_frame[:3, :3]})

    def end(self) -> None:
        """The client is done: the arm brakes to rest and the session ends."""
        self.guard.close()
        if not self.ended:
            self.motions.send({"op": "jog_end"})
