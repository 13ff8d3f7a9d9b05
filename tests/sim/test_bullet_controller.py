"""The simulated CS8 (BulletController): LLI state, power procedures, command checks, tracking,
brakes, control modes, ioctrl, kinematics, recorder and determinism. Real pybullet, stepped in
a plain loop."""
from __future__ import annotations

import dataclasses
import math
import sys
from pathlib import Path

import numpy as np
import pytest

from landscape.robot.arm import VARIANTS
from landscape.robot.cell import Pose
from landscape.robot.controller import (CalibState, EnableState, EstopState, InitState, IoctrlCode,
                                      JointCmd, SettleState, Status)
from landscape.robot.kinematics import Config, ReversingResult
from landscape.sim.recorder import read_recording

sys.path.insert(0, str(Path(__file__).parent))
from bullet_helpers import (DEFAULT_CELL, controller, joints_for, lifted, matrix,  # noqa: E402
                            mount_tool, move_to, run, run_until, tip_position)

ARM = DEFAULT_CELL.arm
HOME = np.array(DEFAULT_CELL.controller.initial_position)
# The arm reaching forward, forearm level: large gravity torques on J2 and J3.
REACHING = np.radians([0.0, 45.0, 45.0, 0.0, 0.0, 0.0])


def test_init_home_and_state_progression():
    ctrl = controller(enabled=False)
    s = ctrl.state()
    assert (s.init, s.enable, s.calib, s.estop) == (
        InitState.NOT_INITIALIZED, EnableState.DISABLED, CalibState.NOT_CALIBRATED,
        EstopState.NO_ESTOP)
    assert ctrl.enable() == Status.ERROR and "not initialised" in ctrl.events[-1]
    assert ctrl.home() == Status.ERROR
    assert ctrl.init() == Status.OK
    s = ctrl.state()
    assert (s.init, s.calib, s.enable) == (InitState.INITIALIZED, CalibState.CALIBRATED,
                                           EnableState.DISABLED)
    assert ctrl.init() == Status.ERROR and "already initialised" in ctrl.events[-1]
    assert ctrl.home() == Status.OK
    run(ctrl, 0.02)
    assert ctrl.state().settle is SettleState.SETTLED
    ctrl.destroy()
    assert ctrl.state().init is InitState.NOT_INITIALIZED
    with pytest.raises(RuntimeError):
        ctrl.step()


def test_enable_takes_its_time_and_nothing_jumps():
    ctrl = controller(enabled=False)
    ctrl.init()
    start = ctrl.get().pos
    assert ctrl.enable() == Status.OK
    assert ctrl.state().enable is EnableState.ENABLING
    states = []
    for _ in range(40):
        ctrl.step()
        states.append(ctrl.state().enable)
        assert np.abs(ctrl.get().pos - start).max() < 1e-6
    cycles = states.index(EnableState.ENABLED) + 1
    assert cycles * ctrl.cycle_time == pytest.approx(DEFAULT_CELL.controller.enable_time)
    assert set(states[:cycles - 1]) == {EnableState.ENABLING}
    assert ctrl.enable() == Status.OK            # already enabled: nothing to do
    assert ctrl.state().settle is SettleState.SETTLED and ctrl.events == []


def test_disable_procedure_then_brakes():
    ctrl = controller()
    assert np.abs(ctrl.get().torque).max() > 1.0        # the drives carry gravity
    assert ctrl.disable() == Status.OK
    assert ctrl.state().enable is EnableState.DISABLING
    run_until(ctrl, lambda: ctrl.state().enable is EnableState.DISABLED, 0.2)
    assert ctrl.cycles * ctrl.cycle_time > DEFAULT_CELL.controller.disable_time
    run(ctrl, 0.02)
    assert np.all(ctrl.get().torque == 0.0)            # drives off: the brakes carry it
    assert ctrl.events == []


def test_estop_disables_at_once_and_must_be_released_before_enabling():
    ctrl = controller()
    ctrl.panel.press_estop()
    s = ctrl.state()
    assert s.enable is EnableState.DISABLED and s.estop is EstopState.ESTOP
    assert "emergency stop" in ctrl.events[-1]
    assert ctrl.enable() == Status.ERROR and "emergency stop" in ctrl.events[-1]
    run(ctrl, 0.2)
    assert ctrl.state().enable is EnableState.DISABLED
    ctrl.panel.release_estop()
    assert ctrl.state().estop is EstopState.NO_ESTOP
    assert ctrl.enable() == Status.OK
    run_until(ctrl, lambda: ctrl.state().enable is EnableState.ENABLED, 0.5)


def test_estop_aborts_enabling():
    ctrl = controller(enabled=False)
    ctrl.init()
    ctrl.enable()
    run(ctrl, 0.02)
    ctrl.panel.press_estop()
    run(ctrl, 0.2)
    assert ctrl.state().enable is EnableState.DISABLED


def _bad_commands():
    vmax, step = np.array(ARM.max_velocity), np.array(ARM.max_velocity) * 0.004
    dvel = DEFAULT_CELL.controller.acceleration_factor * np.array(ARM.max_acceleration) * 0.004
    e1 = np.eye(6)[0]
    return {
        "position": (lambda q: JointCmd(q + e1 * (ARM.joint_max[0] - q[0] + 1e-3), np.zeros(6)),
                     "outside its range"),
        "velocity": (lambda q: JointCmd(q, e1 * vmax[0] * 1.01), "exceeds its maximum"),
        "position jump": (lambda q: JointCmd(q + e1 * step[0] * 1.5, np.zeros(6)),
                          "more than its maximum velocity allows"),
        "velocity jump": (lambda q: JointCmd(q, e1 * dvel[0] * 1.5),
                          "more than a drive can follow"),
        "not a number": (lambda q: JointCmd(q + e1 * math.nan, np.zeros(6)), "NaN"),
    }


@pytest.mark.parametrize("kind", list(_bad_commands()))
def test_an_invalid_command_disables_and_the_arm_does_not_jump(kind):
    make, words = _bad_commands()[kind]
    ctrl = controller()
    run(ctrl, 0.02)
    q = ctrl.get().pos
    ctrl.follower.inject = make(q)
    ctrl.step()   # the cyclic function sends the bad command at the end of this cycle
    assert ctrl.state().enable is EnableState.DISABLED
    assert len(ctrl.events) == 1 and words in ctrl.events[0] and "disabled" in ctrl.events[0]
    for _ in range(100):
        ctrl.step()
        assert np.abs(ctrl.get().pos - q).max() < 1e-6


def test_an_invalid_command_during_a_motion_stops_the_arm_where_it_is():
    ctrl = controller()
    ctrl.follower.move(HOME + np.radians([30, 10, -10, 20, 10, 30]), 1.0, ctrl.cycle_time)
    run(ctrl, 0.5)                                       # mid-way, at full speed
    ctrl.follower.inject = JointCmd(ctrl.get().pos + 0.5, np.zeros(6))
    ctrl.step()
    assert ctrl.state().enable is EnableState.DISABLED
    run(ctrl, 0.02)
    stopped = ctrl.get().pos
    run(ctrl, 0.5)
    assert np.abs(ctrl.get().pos - stopped).max() < 1e-6


@pytest.mark.parametrize("failure", ["raise", "false"])
def test_a_failing_cyclic_function_disables(failure):
    ctrl = controller()
    follower = ctrl.follower

    def cyclic(c):
        follower(c)
        if failure == "raise":
            raise ZeroDivisionError("boom")
        return False

    ctrl.cyclic = cyclic          # swap the cyclic function of a running controller
    q = ctrl.get().pos
    run(ctrl, 0.1)
    assert ctrl.state().enable is EnableState.DISABLED
    assert len(ctrl.events) == 1 and "disabled" in ctrl.events[0]
    why = "ZeroDivisionError: boom" if failure == "raise" else "returned an error"
    assert why in ctrl.events[0]
    assert ctrl.enable() == Status.OK
    run(ctrl, 0.2)                    # still failing: disabled again, with an event
    assert ctrl.state().enable is not EnableState.ENABLED and len(ctrl.events) == 2
    assert np.abs(ctrl.get().pos - q).max() < 1e-6


def test_tracking_with_a_tool_is_tight():
    """Following error of a fast smooth motion carrying the gripper (1.2 kg), and at rest."""
    ctrl = controller()
    mount_tool(ctrl, "gripper")
    length = ctrl.world.mounted.spec.length
    run(ctrl, 0.1)
    rest_joint = np.abs(ctrl.get().pos_err).max()
    q0 = ctrl.get().pos
    follower = ctrl.follower
    follower.errors.clear(), follower.commands.clear(), follower.measured.clear()
    # Quintic moves: J1 at 57 % of its max velocity and 65 % of its max acceleration.
    targets = [q0 + np.radians([110, -25, 30, 90, -50, 120]), q0,
               q0 + np.radians([60, 20, -35, -60, 40, -90])]
    for target in targets:
        follower.move(target, 0.9, ctrl.cycle_time)
    run_until(ctrl, lambda: not follower.plan, 4.0)
    commands = np.array(follower.commands)
    speed = np.abs(np.diff(commands, axis=0)).max(axis=0) / ctrl.cycle_time
    assert speed[0] > 0.55 * ARM.max_velocity[0]
    joint_err = np.abs(np.array(follower.errors)).max()
    measured = np.array(follower.measured)
    tip_err = max(np.linalg.norm(tip_position(ctrl, c, length) - tip_position(ctrl, m, length))
                  for c, m in zip(commands[:-1], measured[1:]))
    print(f"\nfollowing error with the gripper: moving {joint_err:.2e} rad, tool tip "
          f"{tip_err * 1e3:.4f} mm; at rest {rest_joint:.2e} rad")
    # Measured (2 ms physics steps): 2.1e-4 rad (the wrist) and 0.055 mm moving, 1.5e-6 rad
    # at rest; the tool tip must stay well under 0.5 mm.
    assert joint_err < 1e-3 and tip_err < 2.5e-4 and rest_joint < 1e-5
    assert ctrl.events == []


def test_brakes_hold_the_arm_against_gravity():
    ctrl = controller()
    move_to(ctrl, REACHING, 1.0)
    ctrl.disable()
    run_until(ctrl, lambda: ctrl.state().enable is EnableState.DISABLED, 0.2)
    held = ctrl.get().pos
    run(ctrl, 2.0)
    sag = np.abs(ctrl.get().pos - held).max()
    print(f"\ndrift on the brakes over 2 s, arm reaching out: {sag:.1e} rad")
    assert sag < 1e-7


def test_torque_mode_drives_with_the_torque_command():
    ctrl = controller()
    move_to(ctrl, REACHING, 1.0)
    gravity = ctrl.get().torque               # what the drives spend holding the arm
    mode = {"tau": gravity}

    def cyclic(c):
        fbk = c.get()                         # torque mode: feed the measurement back
        c.set(JointCmd(fbk.pos, fbk.vel, mode["tau"]))
        return True

    ctrl.cyclic = cyclic
    assert ctrl.ioctrl(IoctrlCode.SET_TORQUE_MODE) == Status.OK
    start = ctrl.get().pos
    run(ctrl, 0.2)
    assert np.abs(ctrl.get().pos - start).max() < 1e-3            # gravity compensated
    assert np.allclose(ctrl.get().torque, gravity)
    mode["tau"] = gravity * np.array([1, 1, 0.5, 1, 1, 1])       # half the elbow torque
    run(ctrl, 0.2)
    assert ctrl.get().pos[2] - start[2] > 0.02                      # the forearm drops
    assert ctrl.ioctrl(IoctrlCode.SET_POS_VEL_MODE) == Status.OK
    ctrl.cyclic = ctrl.follower
    ctrl.follower.last = ctrl.get().pos                          # hold where it is
    run(ctrl, 0.05)
    here = ctrl.get().pos
    run(ctrl, 0.2)
    assert np.abs(ctrl.get().pos - here).max() < 1e-6
    assert ctrl.state().enable is EnableState.ENABLED and ctrl.events == []


def test_ioctrl():
    ctrl = controller(enabled=False)
    assert "LLI s7.4" in ctrl.ioctrl(IoctrlCode.GET_SOFTWARE_VERSION)
    assert ctrl.ioctrl(IoctrlCode.GET_ROBOT_TYPE) == "TX90"
    assert ctrl.ioctrl(IoctrlCode.GET_JNT_NUMBER) == 6
    assert ctrl.ioctrl(IoctrlCode.GET_CYCLE_TIME) == 0.004
    assert isinstance(ctrl.ioctrl(IoctrlCode.GET_SYNCHRO_TASK_PRIORITY), int)
    lower, upper = ctrl.ioctrl(IoctrlCode.GET_JNT_RANGE)
    assert np.array_equal(lower, ARM.lower) and np.array_equal(upper, ARM.upper)
    assert np.array_equal(ctrl.ioctrl(IoctrlCode.GET_USER_MARKS), np.zeros(6))
    marks = np.radians([1, 2, 3, 4, 5, 6])
    assert ctrl.ioctrl(IoctrlCode.SET_USER_MARKS, marks) == Status.OK
    assert np.array_equal(ctrl.ioctrl(IoctrlCode.GET_USER_MARKS), marks)
    assert ctrl.ioctrl(IoctrlCode.SET_USER_MARKS, [1, 2]) == Status.ERROR
    assert ctrl.ioctrl(IoctrlCode.RECOVER_ABS_JNT_POS) == Status.ERROR
    assert ctrl.ioctrl(99) == Status.ERROR
    assert ctrl.ioctrl(int(IoctrlCode.GET_JNT_NUMBER)) == 6


def test_kinematics_in_the_base_frame():
    ctrl = controller(enabled=False)
    pose, config = ctrl.forward_kin(HOME)
    assert np.allclose(pose[:3, 3], [0.475, 0.05, 0.803])
    assert np.allclose(pose[:3, :3], np.diag([-1.0, 1.0, -1.0]))
    assert np.allclose(matrix(*ctrl.world.flange_pose()), pose, atol=1e-6)   # base at origin
    q, result = ctrl.reverse_kin(HOME + 0.01, pose, Config())
    assert result is ReversingResult.OK and np.allclose(q, HOME, atol=1e-9)
    q, result = ctrl.reverse_kin(HOME, pose, Config(), (ARM.lower, HOME - 0.1))
    assert q is None and result is not ReversingResult.OK


def test_kinematics_stay_in_the_base_frame_when_the_base_moves():
    cell = dataclasses.replace(DEFAULT_CELL, base=Pose((0.1, -0.2, 0.05), (0.0, 0.0, math.pi / 2)))
    ctrl = controller(cell)
    pose, _ = ctrl.forward_kin(ctrl.get().pos)
    assert np.allclose(pose[:3, 3], [0.475, 0.05, 0.803])           # base frame: unchanged
    world = ctrl.world.base_matrix() @ pose
    assert np.allclose(matrix(*ctrl.world.flange_pose()), world, atol=1e-6)


def test_recorder_writes_the_cycles(tmp_path):
    cell = dataclasses.replace(DEFAULT_CELL, recorder=dataclasses.replace(
        DEFAULT_CELL.recorder, path=str(tmp_path / "rec.mcap"), frequency_percent=50))
    ctrl = controller(cell)
    assert ctrl.rec_start() == Status.ERROR                       # rec_init first
    assert ctrl.rec_init() == Status.OK and ctrl.rec_start() == Status.OK
    ctrl.follower.move(HOME + 0.1, 0.2, ctrl.cycle_time)
    run(ctrl, 0.4)
    assert ctrl.rec_stop() == Status.OK
    run(ctrl, 0.1)
    assert ctrl.rec_store() == Status.OK and ctrl.last_record_path == str(tmp_path / "rec.mcap")
    data = read_recording(ctrl.last_record_path)
    assert len(data["t"]) == 50
    assert np.allclose(np.diff(data["t"]), 2 * ctrl.cycle_time)
    assert np.abs(data["cmd_pos"] - data["fbk_pos"]).max() < 1e-4


def _scenario():
    """Commands, I/O and sensor reads; returns everything measured, cycle by cycle."""
    ctrl = controller()
    out = []
    ctrl.follower.move(HOME + np.radians([20, 15, -20, 30, -20, 45]), 0.6, ctrl.cycle_time)
    for k in range(250):
        if k == 100:
            ctrl.dio.write("toolchanger_lock", True)
        if k == 200:
            ctrl.follower.inject = JointCmd(ctrl.get().pos + 1.0, np.zeros(6))
        ctrl.step()
        f = ctrl.get()
        out.append(np.concatenate([f.pos, f.vel, f.pos_err, f.torque, ctrl.read_sensor("force_sensor"),
                                   ctrl.read_sensor("laser_standoff_sensor"),
                                   ctrl.world.part_pose("block_1")[0]]))
    return np.array(out), ctrl.events


def test_same_commands_give_bit_identical_results():
    a, events_a = _scenario()
    b, events_b = _scenario()
    assert np.array_equal(a, b, equal_nan=True) and events_a == events_b and len(events_a) == 1


def test_joint_limits_of_the_cell_are_enforced():
    arm = dataclasses.replace(ARM, joint_max=(0.5,) + ARM.joint_max[1:])
    ctrl = controller(dataclasses.replace(DEFAULT_CELL, arm=arm))
    assert ctrl.ioctrl(IoctrlCode.GET_JNT_RANGE)[1][0] == 0.5
    ctrl.follower.move(HOME + np.array([0.6, 0, 0, 0, 0, 0]), 1.0, ctrl.cycle_time)
    run(ctrl, 1.0)
    assert ctrl.state().enable is EnableState.DISABLED and "joint 1 position" in ctrl.events[0]
    assert ctrl.get().pos[0] <= 0.5


@pytest.mark.parametrize("variant", ["TX90L", "TX90XL"])
def test_the_longer_variants_run_in_the_same_cell(variant):
    cell = dataclasses.replace(DEFAULT_CELL, arm=VARIANTS[variant])
    ctrl = controller(cell)
    assert ctrl.ioctrl(IoctrlCode.GET_ROBOT_TYPE) == variant
    move_to(ctrl, HOME + np.radians([20, 10, -10, 0, 10, 0]), 0.5)
    pose, _ = ctrl.forward_kin(ctrl.get().pos)
    assert np.allclose(matrix(*ctrl.world.flange_pose()), pose, atol=1e-5)
    assert ctrl.events == []


def test_flange_pose_follows_the_commanded_tool_path():
    """Cartesian check: commanding IK solutions puts the flange where asked."""
    ctrl = controller()
    target = lifted(matrix(*ctrl.world.flange_pose()), -0.2)
    move_to(ctrl, joints_for(ctrl, target), 1.0)
    assert np.allclose(matrix(*ctrl.world.flange_pose()), target, atol=1e-6)
