"""Digital I/O by name and by unit/bit, the panel, and the world behind the wired inputs: parts
in zones, the tool changer, the gripper and the vacuum cup."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

from landscape.robot.controller import (DioStatus, DoutValue, EstopState, IoType, Status)
from landscape.sim.dio import EdgeDetector

sys.path.insert(0, str(Path(__file__).parent))
from bullet_helpers import (controller, joints_for, lifted, matrix, mount_tool,  # noqa: E402
                            move_to, run, run_until)

# Flange pointing straight down, tool x along world x (the gripper's fingers close along x).
DOWN = np.diag([1.0, -1.0, -1.0, 1.0])


def at(xyz) -> np.ndarray:
    pose = DOWN.copy()
    pose[:3, 3] = xyz
    return pose


def test_io_by_name_and_by_unit_and_bit():
    ctrl = controller(enabled=False)
    dio = ctrl.dio
    assert dio.read_unit(0) == 0b10                        # e-stop released, door closed
    ctrl.panel.open_door()
    assert dio.read_unit(0) == 0 and not dio.read("door_closed")
    ctrl.panel.press_estop()
    assert dio.read_unit(0) == 0b01 and ctrl.state().estop is EstopState.ESTOP
    ctrl.panel.release_estop()
    ctrl.panel.close_door()

    assert dio.read_unit(2) == 0
    dio.write_unit(2, bits_on=0b11000)
    assert dio.read_unit(2) == 0b11000 and dio.read("lamp_green") and dio.read("lamp_red")
    dio.write_unit(2, bits_off=0b01000)
    assert dio.read_unit(2) == 0b10000
    dio.write("lamp_green", True)
    assert dio.read_unit(2) == 0b11000
    assert dio.lookup("lamp_red").mask == 0b10000 and dio.lookup("nothing") is None

    with pytest.raises(ValueError, match="holds inputs"):
        dio.write_unit(0, bits_on=1)
    with pytest.raises(ValueError, match="no outputs at bits 0x200"):
        dio.write_unit(2, bits_on=1 << 9)
    with pytest.raises(ValueError, match="both set and cleared"):
        dio.write_unit(2, bits_on=1 << 3, bits_off=1 << 3)
    with pytest.raises(KeyError):
        dio.read_unit(9)
    with pytest.raises(ValueError, match="is an input"):
        dio.write("estop", True)
    with pytest.raises(KeyError):
        dio.read("nothing")


def test_lli_io_calls():
    ctrl = controller(enabled=False)
    din = ctrl.get_din_id("door_closed")
    assert din.type is IoType.D_INPUT and ctrl.read_dio(din) is DioStatus.ONE
    ctrl.panel.open_door()
    assert ctrl.read_dio(din) is DioStatus.ZERO
    dout = ctrl.get_dout_id("lamp_red")
    assert dout.type is IoType.D_OUTPUT and ctrl.read_dio(dout) is DioStatus.ZERO
    assert ctrl.write_dout(dout, DoutValue.ONE) == Status.OK
    assert ctrl.read_dio(dout) is DioStatus.ONE and ctrl.dio.read_unit(2) == 0b10000
    assert ctrl.get_dout_id("estop").type is IoType.UNDEFINED          # an input, not an output
    assert ctrl.get_din_id("nothing").type is IoType.UNDEFINED
    assert ctrl.read_dio(ctrl.get_din_id("nothing")) is DioStatus.UNDEFINED
    assert ctrl.write_dout(din, DoutValue.ONE) == Status.ERROR
    assert "not a digital output" in ctrl.events[-1]


def test_edge_detector():
    edges = EdgeDetector(0b0110)
    assert edges.update(0b0011) == (0b0001, 0b0100)
    assert edges.update(0b0011) == (0, 0)
    assert edges.update(0) == (0, 0b0011)


def test_part_in_zone_inputs_follow_the_world():
    ctrl = controller(enabled=False)
    dio = ctrl.dio
    run(ctrl, 0.1)
    assert dio.read("part_at_pick") and not dio.read("part_at_place")
    ctrl.panel.place_part("block_2", (0.73, 0.0, 0.2201))             # by hand, onto "place"
    run(ctrl, 0.1)
    assert dio.read("part_at_place") and dio.read("part_at_pick")
    for name in ("block_1", "plate_1"):
        ctrl.panel.remove_part(name)
    run(ctrl, 0.1)
    assert not dio.read("part_at_pick")
    assert dio.read_unit(1) & dio.lookup("part_at_place").mask


def test_tool_changer_couples_only_a_tool_at_the_flange_and_returns_it_to_the_rack():
    ctrl = controller()
    dio = ctrl.dio
    dio.write("toolchanger_lock", True)          # nothing at the flange: the lock closes on air
    run(ctrl, 0.05)
    assert ctrl.world.mounted is None and not dio.read("tool_present")
    dio.write("toolchanger_lock", False)

    tool = ctrl.world.tools["vacuum"]
    slot = matrix(*tool.plate_pose())
    move_to(ctrl, joints_for(ctrl, lifted(slot, 0.1)), 1.0)
    move_to(ctrl, joints_for(ctrl, slot), 0.6)
    assert dio.read("tool_present") and ctrl.world.mounted is None   # there, not yet coupled
    dio.write("toolchanger_lock", True)
    run(ctrl, 0.05)
    assert ctrl.world.mounted is tool
    move_to(ctrl, joints_for(ctrl, lifted(slot, 0.2)), 0.6)
    assert np.allclose(matrix(*tool.plate_pose()), matrix(*ctrl.world.flange_pose()), atol=1e-5)
    assert dio.read("tool_present")

    move_to(ctrl, joints_for(ctrl, slot), 0.6)                       # back into its slot
    dio.write("toolchanger_lock", False)
    move_to(ctrl, joints_for(ctrl, lifted(slot, 0.2)), 0.6)
    assert ctrl.world.mounted is None and not dio.read("tool_present")
    assert np.allclose(matrix(*tool.plate_pose()), slot, atol=1e-5)  # docked in the rack
    assert ctrl.events == []


def test_gripper_picks_and_places_a_part():
    ctrl = controller()
    dio = ctrl.dio
    dio.write("gripper_close", True)             # no gripper mounted: nothing happens
    run(ctrl, 0.3)
    assert not dio.read("gripper_closed")
    dio.write("gripper_close", False)

    mount_tool(ctrl, "gripper")
    block = np.array(ctrl.world.part_pose("block_2")[0])
    grasp = at(block + [0.0, 0.0, 0.16])        # finger tips level with the block's centre
    move_to(ctrl, joints_for(ctrl, lifted(grasp, 0.1)), 1.2)
    move_to(ctrl, joints_for(ctrl, grasp), 0.6)
    dio.write("gripper_close", True)
    assert not dio.read("gripper_closed")
    run_until(ctrl, lambda: dio.read("gripper_closed"), 0.5)
    assert ctrl.world.mounted.held == ctrl.world.parts["block_2"].body

    place = grasp.copy()
    place[0, 3] = 0.73
    move_to(ctrl, joints_for(ctrl, lifted(grasp, 0.1)), 0.6)
    lifted_block = np.array(ctrl.world.part_pose("block_2")[0])
    assert lifted_block[2] == pytest.approx(block[2] + 0.1, abs=1e-3)
    move_to(ctrl, joints_for(ctrl, lifted(place, 0.1)), 0.8)
    move_to(ctrl, joints_for(ctrl, lifted(place, 0.001)), 0.6)
    assert dio.read("part_at_place")
    dio.write("gripper_close", False)
    assert not dio.read("gripper_closed") and ctrl.world.mounted.held is None
    run(ctrl, 0.3)
    move_to(ctrl, joints_for(ctrl, lifted(place, 0.1)), 0.6)
    run(ctrl, 0.3)
    placed = np.array(ctrl.world.part_pose("block_2")[0])
    assert placed == pytest.approx([0.73, block[1], block[2]], abs=2e-3)  # resting on the table
    assert ctrl.events == []


def test_vacuum_cup_holds_a_part_it_touches():
    ctrl = controller()
    dio = ctrl.dio
    mount_tool(ctrl, "vacuum")
    plate = np.array(ctrl.world.part_pose("plate_1")[0])
    touch = at(plate + [0.0, 0.0, 0.005 + 0.12 + 0.001])   # cup face 1 mm above the plate
    dio.write("vacuum_on", True)                            # suction on in the air: nothing held
    move_to(ctrl, joints_for(ctrl, lifted(touch, 0.1)), 1.2)
    assert not dio.read("vacuum_ok")
    move_to(ctrl, joints_for(ctrl, touch), 0.6)
    assert dio.read("vacuum_ok")
    move_to(ctrl, joints_for(ctrl, lifted(touch, 0.1)), 0.6)
    assert ctrl.world.part_pose("plate_1")[0][2] == pytest.approx(plate[2] + 0.099, abs=2e-3)
    dio.write("vacuum_on", False)
    assert not dio.read("vacuum_ok")
    run(ctrl, 0.5)
    assert ctrl.world.part_pose("plate_1")[0][2] == pytest.approx(plate[2], abs=2e-3)
    assert ctrl.events == []
