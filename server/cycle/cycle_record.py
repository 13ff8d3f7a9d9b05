"""Each cycle's record: its row of the feedback ring (feedback.py), with the arm model's
torques for the motion the drives just played (arm_dynamics.py). The Executor (executor.py)
computes the cycle; this writes down what it commanded and what it read."""
from __future__ import annotations

import numpy as np

from landscape.robot.controller import EstopState
from landscape.server.cycle.feedback import MODEL_TAU, FeedbackRing


class CycleRecord:
    """`ring` receives a row per cycle (None: nothing is written); `dynamics` (ArmDynamics,
    or None) computes the model torques in it."""

    def __init__(self, ring: FeedbackRing | None, cycle_time: float, dynamics=None):
        self.ring, self.cycle_time, self.dynamics = ring, cycle_time, dynamics
        self.sequence = ring.head + 1 if ring is not None else 0   # goes on after a restart
        self.setpoints: tuple | None = None   # the last three cycles' (6,), newest first
        self._stamp = np.zeros(3)          # SEQ, TIME, WALL of the row being written
        self._power = np.zeros(2)          # ENABLE, ESTOP
        self._no_model = np.full(MODEL_TAU.stop - MODEL_TAU.start, np.nan)

    @property
    def watched(self) -> bool:
        """Whether a reader wants this cycle's row whole (FeedbackRing.watch)."""
        return self.ring is not None and self.ring.watched

    def model_torques(self, fbk, pos: np.ndarray, wanted: bool = True) -> np.ndarray | float:
        """The arm model's torques for the cycle the drives just played (NaN unless `wanted`):
        they went from the setpoint of two cycles ago to last cycle's (linearly, LLI 5.3.12),
        so the commanded acceleration is the second difference of the last three setpoints.
        Then `pos` (this cycle's) becomes the newest."""
        past = self.setpoints
        if past is None:
            past = (fbk.pos.copy(),) * 3
        model = np.nan
        if wanted and self.dynamics is not None:
            acceleration = (past[0] - 2.0 * past[1] + past[2]) / (self.cycle_time ** 2)
            model = self.dynamics.torques(fbk.pos, fbk.vel, acceleration)
        # Shifted by reference, not copied row by row: every cycle pays for this one.
        self.setpoints = (np.array(pos, dtype=float), past[0], past[1])
        return model

    def set_payload(self, parameters) -> None:
        """What the flange carries now (10 dynamic parameters, arm_dynamics.py)."""
        if self.dynamics is not None:
            self.dynamics.set_payload(parameters)

    def write(self, ctrl, fbk, pos, state, wall: float, sensors, io_image, model) -> None:
        """This cycle's row, stamped `wall` (unix s); then the sequence goes on."""
        if self.ring is None:
            return
        stamp, power = self._stamp, self._power
        stamp[0], stamp[1], stamp[2] = self.sequence, getattr(ctrl, "time", 0.0), wall
        power[0] = int(state.enable)
        power[1] = 1.0 if state.estop is EstopState.ESTOP else 0.0
        # Into the ring's slot in one numpy call, in the row's column order (feedback.py):
        # every cycle pays for this.
        np.concatenate((stamp, fbk.pos, fbk.vel, pos, fbk.torque, power, sensors, io_image,
                        self._no_model if np.isscalar(model) else model),
                       out=self.ring.slot(self.sequence))
        self.ring.publish(self.sequence)
        self.sequence += 1
