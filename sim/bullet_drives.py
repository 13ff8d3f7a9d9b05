"""The simulated CS8's drives and brakes: the arm's physics on pybullet, one cycle at a time (the
plant that `BulletController`, bullet_controller.py, commands with the LLI's semantics).

The drives (LLI 5.3.12). Each cycle runs `substeps` pybullet steps; in position/velocity mode
the drives micro-interpolate linearly from the last command to the new one, one target per
substep, with pybullet's constraint motor set dead-beat (position gain 1, velocity gain 1,
target velocity 0: each substep ends on its target when the torque suffices), torque limited
to effort_factor * max effort and speed to max velocity. The velocity command is checked and
recorded but the intra-cycle path is the straight line (robust to commands whose velocity is
zero or inconsistent). The torque feed-forward adds to the motor torque. In torque mode the
motors are off and the torque command (clipped to the same limit) drives the joints.

The brakes: braked, the joints stop (a zero-velocity hold, limited to brake_factor * max
effort) and, once still, are held where they stopped (a position hold), so nothing drifts and
nothing jumps. Holding (the controller enabling or disabling), the drives hold the position
measured when it began.

Feedback (`fbk`, what the LLI's get() returns): measured position, velocity, following error
(command, or the held position, minus measured) and torque (motor, averaged over the cycle's
substeps, plus feed-forward; the torque command in torque mode; 0 while braked: the drives are
off and the brakes carry the load).

Single-threaded, as the controller.
"""
from __future__ import annotations

import enum
import functools

import numpy as np

from landscape.sim.native_output import silenced

with silenced():   # pybullet's banner
    import pybullet as pb
    from pybullet_utils.bullet_client import BulletClient

from landscape.robot.controller import JointFbk, SettleState

SETTLE_SPEED = 1e-3            # rad/s: slower than this on every joint ...
SETTLE_ERROR = 1e-4            # rad: ... and this close to the command is SETTLED
BRAKE_LATCH_SPEED = 1e-3       # rad/s: braked joints slower than this are held in place


class _BoundClient(BulletClient):
    """pybullet's client wrapper with each function bound to the client once, on first use:
    BulletClient binds it again on every call (a partial and an inspect per call: a third of
    what the world's per-cycle reads cost)."""

    def __getattr__(self, name: str):
        attribute = super().__getattr__(name)
        if name != "disconnect":   # (which also marks the client gone)
            self.__dict__[name] = attribute
        return attribute

    @property
    def client_id(self) -> int:
        """pybullet's id of this client, for its functions called directly."""
        return self._client


def connect(cycle_time: float, substeps: int) -> _BoundClient:
    """A pybullet client of its own (DIRECT mode) whose step is one of a cycle's substeps."""
    with silenced():   # "argv[0]="
        bc = _BoundClient(pb.DIRECT)
    bc.setPhysicsEngineParameter(fixedTimeStep=cycle_time / substeps,
                                 deterministicOverlappingPairs=1)
    return bc


class _Drive(enum.Enum):
    BRAKED = "braked"          # drives off, brakes on
    HOLDING = "holding"        # drives on, holding a fixed position (enabling, disabling)
    POSVEL = "posvel"          # following commands in position/velocity mode
    TORQUE = "torque"          # following torques in torque mode


class Drives:
    """The drives and brakes of `world`'s arm (on client `bc`), as the cell's `arm` and
    controller `spec` rate them; braked, holding the arm where it is. `cycle()` runs one cycle.

    `fbk` (JointFbk) and `settle` are the latest cycle's; `cmd_pos`, `cmd_vel` the last command
    taken; `effort` the torque limit (N*m, 6 values).
    """

    def __init__(self, bc: _BoundClient, world, arm, spec):
        self._bc, self._body, self._joint_ids = bc, world.arm, world.joints
        self._vmax = np.array(arm.max_velocity).tolist()
        self.effort = (spec.effort_factor * np.array(arm.max_effort)).tolist()
        self._brake_list = (spec.brake_factor * np.array(arm.max_effort)).tolist()

        # The per-cycle pybullet calls, bound once to this client, arm and joints.
        cid, body, joints = bc.client_id, world.arm, world.joints
        self._physics_step = functools.partial(pb.stepSimulation, physicsClientId=cid)
        self._motors = functools.partial(pb.setJointMotorControlArray, body, joints,
                                         physicsClientId=cid)
        self._joint_states = functools.partial(pb.getJointStates, body, joints,
                                               physicsClientId=cid)
        self._fractions = [(k + 1) / spec.substeps for k in range(spec.substeps)]
        self._zeros, self._ones = [0.0] * 6, [1.0] * 6

        # Commands: the last one taken (lists, for the per-cycle path) and where this cycle's
        # interpolation starts; the held position when not following.
        self._mode = _Drive.BRAKED
        self._braking = False
        self.settle = SettleState.NOT_SETTLED
        self._hold = [s[0] for s in self._joint_states()]
        self.fbk = JointFbk(np.array(self._hold), np.zeros(6), np.zeros(6), np.zeros(6))
        self.command(self._hold, self._zeros, self._zeros)
        self.brake()

    def command(self, pos: list, vel: list, tau: list) -> None:
        """Take a command (rad, rad/s, N*m; lists of 6 floats) as the one to follow."""
        self.cmd_pos, self.cmd_vel, self._tau = pos, vel, tau
        self._ffw = any(tau)

    # ---- the cycle ----------------------------------------------------------------------------

    def cycle(self) -> None:
        """cycle_time of physics in the current mode, then the feedback."""
        drive, motors, physics = self._mode, self._motors, self._physics_step
        following = drive is _Drive.POSVEL or drive is _Drive.TORQUE
        if drive is _Drive.POSVEL:
            start = self._start
            delta = [e - s for s, e in zip(start, self.cmd_pos)]
            tau = self._tau if self._ffw else None
            applied = [0.0] * 6   # the motors' torques summed over the substeps
            for f in self._fractions:
                target = [s + f * d for s, d in zip(start, delta)]
                motors(pb.POSITION_CONTROL, targetPositions=target, targetVelocities=self._zeros,
                       positionGains=self._ones, velocityGains=self._ones,
                       forces=self.effort)
                if tau is not None:
                    motors(pb.TORQUE_CONTROL, forces=tau)
                physics()
                states = self._joint_states()
                applied = [a + s[3] for a, s in zip(applied, states)]
            self._start = self.cmd_pos
        elif drive is _Drive.TORQUE:
            for _ in self._fractions:
                motors(pb.TORQUE_CONTROL, forces=self._tau)
                physics()
        else:
            for _ in self._fractions:
                physics()

        # Feedback, in plain lists until the arrays are built: numpy is slow on 6 values.
        if drive is not _Drive.POSVEL:   # (following, the last substep has read them)
            states = self._joint_states()
        pos = [s[0] for s in states]
        vel = [s[1] for s in states]
        speed = max(map(abs, vel))
        if drive is _Drive.POSVEL:
            # Averaged over the cycle, as a drive's current filtered at the cycle rate: the
            # dead-beat motors change speed in the first substep, so the last one alone would
            # miss the inertial torque.
            n = len(self._fractions)
            torque = ([a / n + t for a, t in zip(applied, self._tau)] if self._ffw
                      else [a / n for a in applied])
        elif drive is _Drive.TORQUE:
            torque = self._tau
        elif drive is _Drive.HOLDING:
            torque = [s[3] for s in states]
        else:
            torque = self._zeros
            if self._braking and speed < BRAKE_LATCH_SPEED:
                self._hold_position(pos, self._brake_list)
                self._braking = False
        reference = self.cmd_pos if following else self._hold
        err = [c - p for c, p in zip(reference, pos)]
        self.settle = (SettleState.SETTLED
                       if speed < SETTLE_SPEED and max(map(abs, err)) < SETTLE_ERROR
                       else SettleState.NOT_SETTLED)
        self.fbk = JointFbk(np.array(pos), np.array(vel), np.array(err), np.array(torque))

    def reference(self) -> tuple[list, list]:
        """The position and velocity aimed at: the command followed, else the held position."""
        if self._mode is _Drive.POSVEL or self._mode is _Drive.TORQUE:
            return self.cmd_pos, self.cmd_vel
        return self._hold, self._zeros

    # ---- modes --------------------------------------------------------------------------------

    @property
    def braked(self) -> bool:
        return self._mode is _Drive.BRAKED

    def brake(self) -> None:
        """Brakes on: stop the joints (zero velocity, brake torque); once they are still, hold
        them there (cycle() switches; at once if they are still already)."""
        self._mode = _Drive.BRAKED
        if float(np.max(np.abs(self.fbk.vel))) < BRAKE_LATCH_SPEED:
            self._hold_position(self.fbk.pos, self._brake_list)
            self._braking = False
        else:
            self._hold = self.fbk.pos.tolist()
            self._motors(pb.VELOCITY_CONTROL, targetVelocities=self._zeros,
                         forces=self._brake_list)
            self._braking = True

    def power_on(self) -> None:
        """Brakes off, the drives holding the arm where it is."""
        self._clamp_velocity()
        self.hold()
        self._braking = False

    def hold(self) -> None:
        """The drives hold the arm where it is."""
        self._hold_position(self.fbk.pos, self.effort)
        self._mode = _Drive.HOLDING

    def engage(self, torque: bool, bumpless: bool = False) -> None:
        """The drives follow the commands in torque or position/velocity mode, from a command to
        stay where the arm is; `bumpless` (a switch while following): into torque mode, carry on
        with the velocity and the torque the drives spend now, until the next command."""
        fbk, carry = self.fbk, bumpless and torque
        self.command(fbk.pos.tolist(), fbk.vel.tolist() if carry else self._zeros,
                     fbk.torque.tolist() if carry else self._zeros)
        self._start = self.cmd_pos
        if torque:
            self._motors(pb.VELOCITY_CONTROL, targetVelocities=self._zeros, forces=self._zeros)
            self._mode = _Drive.TORQUE
        else:
            self._clamp_velocity()
            self._hold_position(self.cmd_pos, self.effort)
            self._mode = _Drive.POSVEL

    def _clamp_velocity(self) -> None:
        # setJointMotorControlArray cannot pass maxVelocity; the motors keep it once set.
        for j, q, vmax in zip(self._joint_ids, self.fbk.pos.tolist(), self._vmax):
            self._bc.setJointMotorControl2(self._body, j, pb.POSITION_CONTROL,
                                           targetPosition=q, force=0.0, maxVelocity=vmax)

    def _hold_position(self, pos, forces) -> None:
        """Dead-beat position hold at `pos` (rad, 6 values) with torques up to `forces`."""
        self._hold = [float(q) for q in pos]
        self._motors(pb.POSITION_CONTROL, targetPositions=self._hold,
                     targetVelocities=self._zeros, positionGains=self._ones,
                     velocityGains=self._ones, forces=forces)
