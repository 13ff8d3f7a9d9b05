"""The scene follows the world through explicit calls; models are snapshots."""
from __future__ import annotations

import numpy as np
import pytest

from landscape.server.planning.collision import CollisionModelError, check_motion
from landscape.robot.units import pose_matrix


def test_mounting_moves_a_tool_from_its_slot_to_the_flange(scene, kit):
    slot = kit.cell.world.tools[0].slot
    assert np.allclose(scene.tool_pose("gripper"), pose_matrix(slot.xyz, slot.rpy))
    scene.mount_tool("gripper")
    assert scene.mounted == "gripper" and scene.tool_pose("gripper") is None
    flange_shapes = [g for g in scene.model().geometries if g.body == "gripper"]
    assert flange_shapes and all(g.link == 6 for g in flange_shapes)
    assert scene.unmount_tool() == "gripper"
    assert scene.mounted is None
    assert np.allclose(scene.tool_pose("gripper"), pose_matrix(slot.xyz, slot.rpy))


def test_a_tool_let_go_elsewhere_stays_there(scene):
    scene.mount_tool("vacuum")
    somewhere = pose_matrix((0.6, 0.2, 0.215), (np.pi, 0, 0))
    scene.unmount_tool(at=somewhere)
    assert np.allclose(scene.tool_pose("vacuum"), somewhere)
    assert all(g.link == 0 for g in scene.model().geometries if g.body == "vacuum")


def test_tool_changes_that_cannot_be(scene):
    with pytest.raises(CollisionModelError, match="no tool"):
        scene.unmount_tool()
    with pytest.raises(CollisionModelError, match="unknown tool"):
        scene.mount_tool("welder")
    scene.mount_tool("gripper")
    with pytest.raises(CollisionModelError, match="mounted already"):
        scene.mount_tool("vacuum")
    with pytest.raises(CollisionModelError, match="finger gap"):
        scene.set_finger_gap(0.2)
    scene.attach_part("block_1", in_flange=pose_matrix((0, 0, 0.15), (0, 0, 0)))
    with pytest.raises(CollisionModelError, match="release it first"):
        scene.unmount_tool()


def test_finger_gap_only_for_a_mounted_gripper(scene):
    with pytest.raises(CollisionModelError, match="no gripper"):
        scene.set_finger_gap(0.02)
    scene.mount_tool("vacuum")
    with pytest.raises(CollisionModelError, match="no gripper"):
        scene.set_finger_gap(0.02)


def test_the_finger_gap_moves_the_fingers(scene):
    scene.mount_tool("gripper")

    def left_finger_x():
        g = next(g for g in scene.model().geometries if g.name == "gripper/finger_left")
        return g.placement[0, 3]

    open_x = left_finger_x()
    scene.set_finger_gap(0.02)
    assert left_finger_x() - open_x == pytest.approx(0.03)    # each finger 3 cm inwards


def test_attach_and_release_keep_the_part_where_it_is(scene, kit):
    scene.mount_tool("gripper")
    q = kit.ik((0.5, -0.15, 0.37))
    lying = scene.part_pose("block_1")
    scene.attach_part("block_1", q=q)
    assert scene.held == "block_1" and scene.part_pose("block_1") is None
    held = next(g for g in scene.model().geometries if g.body == "block_1")
    assert held.link == 6
    assert np.allclose(held.placement[:3, 3], (0.0, 0.0, 0.15), atol=1e-9)
    moved = kit.ik((0.5, 0.1, 0.5), q)
    released = scene.release_part(moved)
    assert np.allclose(released[:3, 3], lying[:3, 3] + (0, 0.25, 0.13), atol=1e-9)
    assert scene.held is None


def test_parts_that_cannot_be_attached(scene, kit):
    with pytest.raises(CollisionModelError, match="unknown part"):
        scene.attach_part("anvil", q=kit.q0)
    with pytest.raises(CollisionModelError, match="either q or in_flange"):
        scene.attach_part("block_1")
    with pytest.raises(CollisionModelError, match="no part is held"):
        scene.release_part(kit.q0)
    scene.remove_part("block_1")
    with pytest.raises(CollisionModelError, match="not in the cell"):
        scene.attach_part("block_1", q=kit.q0)
    scene.attach_part("block_2", q=kit.q0)
    with pytest.raises(CollisionModelError, match="held already"):
        scene.attach_part("plate_1", q=kit.q0)


def test_removing_and_placing_parts(scene):
    assert "block_2" in scene.model().bodies()
    scene.remove_part("block_2")
    assert "block_2" not in scene.model().bodies() and scene.part_pose("block_2") is None
    scene.place_part("block_2", pose_matrix((0.4, 0.3, 0.22), (0, 0, 0.5)))
    assert "block_2" in scene.model().bodies()
    with pytest.raises(CollisionModelError, match="4, 4"):
        scene.place_part("block_2", np.eye(3))


def test_a_model_is_a_snapshot(scene, kit):
    before = scene.model()
    assert scene.model() is before                     # cached until the scene changes
    a, b = kit.ik((0.6, -0.3, 0.45)), kit.ik((0.6, 0.3, 0.45))
    middle = kit.kin.forward((a + b) / 2)[:3, 3]
    scene.place_part("block_1", pose_matrix(middle, (0, 0, 0)))
    after = scene.model()
    assert after is not before
    assert check_motion(before, [a, b], 0.004).clear
    assert check_motion(after, [a, b], 0.004).contact.bodies[1] == "block_1"


def test_allowed_contacts_name_known_bodies(scene):
    from landscape.server.planning.collision import AllowedContact
    with pytest.raises(CollisionModelError, match="unknown body"):
        scene.allow(AllowedContact("oops", "link6", "tabel"))
    with pytest.raises(CollisionModelError, match="no tool"):
        scene.grasp("block_1")


def test_the_world_s_part_poses_are_taken_unless_the_scene_changed_since_they_were_read(
        scene, kit):
    lying = scene.part_pose("block_1")
    model, version = scene.model(), scene.version
    nudged = lying @ pose_matrix((0.0005, 0, 0), (0, 0, 0))       # under a millimetre
    assert scene.follow_parts({"block_1": nudged}, version)
    assert scene.model() is model                                 # nothing to recompile
    moved = pose_matrix((0.3, 0.3, 0.22), (0, 0, 0.5))
    stale = scene.version
    scene.attach_part("block_2", kit.q0)                          # the device: a grasp
    assert not scene.follow_parts({"block_1": moved}, stale)      # read before it: dropped
    assert np.allclose(scene.part_pose("block_1"), lying)
    held = pose_matrix((0.6, 0.0, 0.22), (0, 0, 0))
    assert scene.follow_parts({"block_1": moved, "block_2": held}, scene.version)
    assert np.allclose(scene.part_pose("block_1"), moved)
    assert scene.held == "block_2" and scene.part_pose("block_2") is None   # the tool's
