"""The drives: on (Activate), off (Deactivate, the safety actions), and off at a fault (seed 3.1).

Given the state machine (state_machine.py), the motions (motion_control.py) and the link to the
controller; it changes the state only through the state machine's compare-and-set.
"""
from __future__ import annotations

import contextlib
import logging
from typing import Callable

from landscape.robot.controller import EnableState, Status
from landscape.server.device import states
from landscape.server.device.motion_control import MotionControl
from landscape.server.device.state_machine import StateMachine
from landscape.server.device.states import State
from landscape.server.errors import ControllerFailure
from landscape.server.events import alarms
from landscape.server.link.clock import CycleProcessError
from landscape.server.link.controller_link import ControllerLink

log = logging.getLogger(__name__)

# A safety stop brakes at the arm's full deceleration: the TX90 at full speed stops within
# max velocity / max acceleration = 1/3 s (main axes) and 1/5 s (wrist), then settles.
SAFETY_STOP_TIMEOUT = 2.0


class Power:
    def __init__(self, state: StateMachine, motions: MotionControl, link: ControllerLink,
                 enable_timeout: float = 5.0):
        self.state, self.motions, self.link = state, motions, link
        self.enable_timeout = enable_timeout

    def activate(self) -> None:
        """Drives on, then Resting; if anything fails on the way (the e-stop, the controller,
        the lock holder leaving meanwhile), the drives are turned off again."""
        state, epoch = self.state, self.state.epoch
        try:
            self.command_controller("enable")
            self.wait(lambda: state.power is EnableState.ENABLED or state.estop
                      or self.link.lost is not None or state.epoch != epoch,
                      self.enable_timeout)
            with state.atomic():
                state.check_epoch()
                if state.power is not EnableState.ENABLED:
                    why = state.error or ("e-stop pressed" if state.estop else "timed out")
                    raise ControllerFailure(f"the drives did not come on ({why})")
                state.transition({State.INACTIVE}, State.RESTING, "activated")
        except BaseException:
            with contextlib.suppress(Exception):
                self.link.proxy.disable()
            raise

    def power_down(self, reason: str, timeout: float = SAFETY_STOP_TIMEOUT) -> None:
        """Stop any motion (no new one can start meanwhile), disable, wait, then Inactive.
        Drives that do not go off are a fault: Error and ControllerFailure, never Inactive."""
        state = self.state
        with self.motions.no_new_motion():
            stopped = self.motions.stop_for_safety(timeout)
            if not stopped:
                log.error("the motion did not stop within %.1f s; disabling the drives now",
                          timeout)
            self.command_controller("disable")
            self.wait(lambda: state.power is EnableState.DISABLED or self.link.lost is not None,
                      self.enable_timeout)
            if self.link.lost is not None:
                raise ControllerFailure(f"the controller is lost: {self.link.lost}")
            if state.power is not EnableState.DISABLED:
                why = f"the drives did not go off within {self.enable_timeout:g} s ({reason})"
                self.fault(alarms.CONTROLLER, why)
                raise ControllerFailure(why)
            with state.atomic():
                if state.state in states.ACTIVE:
                    state.transition(states.ACTIVE, State.INACTIVE, reason)

    def fault(self, code: int, message: str) -> None:
        """Into Error with an alarm and the drives off (a fault found above the controller,
        such as a compliance panic that asks for it)."""
        if self.state.enter_error(code, message):
            with contextlib.suppress(ControllerFailure):
                self.command_controller("disable")

    def drives_may_be_on(self) -> bool:
        """The drives are on, or coming on (an Activate that was under way), as far as the
        controller says (or last reported, if it cannot say)."""
        try:
            power = self.link.proxy.state().enable
        except (CycleProcessError, TimeoutError):
            power = self.state.power
        return power is not EnableState.DISABLED

    def command_controller(self, method: str) -> None:
        try:
            result = getattr(self.link.proxy, method)()
        except (CycleProcessError, TimeoutError) as error:
            raise ControllerFailure(f"the controller did not answer {method}: {error}") from None
        if result is not Status.OK:
            raise ControllerFailure(f"the controller refused {method}")

    def wait(self, done: Callable[[], bool], timeout: float) -> bool:
        return self.state.wait_controller(done, timeout)
