"""Motions of the default TX90 cell planned by the server's Planner, checked against the scene:
the table, the rack, held and put-down parts, allowed contacts and exclusions."""
from __future__ import annotations

import numpy as np
import pytest

from landscape.server.planning.collision import AllowedContact, CollisionModelError, check_motion
from landscape.robot.units import pose_matrix

ARM = {"link1", "link2", "link3", "link4", "link5", "link6"}


def beside_table(kit):
    """Flange 12 cm above the floor on either side of the table (its top is at 0.2 m)."""
    return kit.ik((0.6, -0.55, 0.12)), kit.ik((0.6, 0.55, 0.12))


def test_a_joint_move_through_the_table_names_the_table_and_the_link(kit, scene):
    a, b = beside_table(kit)
    trajectory = kit.plan([a, b])
    result = check_motion(scene.model(), trajectory.positions, trajectory.dt, trajectory.marks)
    contact = result.contact
    assert contact is not None
    assert contact.bodies[1] == "table" and contact.bodies[0] in ARM
    assert contact.distance < 0.005
    assert 0.0 < contact.time < trajectory.duration
    assert contact.fraction == pytest.approx(contact.time / trajectory.duration)
    assert contact.sample == int(contact.time / trajectory.dt + 1e-9)
    assert contact.segment == 1                     # on the way to waypoint 1
    assert np.allclose(contact.q, trajectory.positions[contact.sample], atol=0.05)
    assert "table" in str(contact) and contact.metadata()["body_b"] == "table"


def test_the_same_target_over_the_table_is_clear(kit, scene):
    a, b = beside_table(kit)
    over = [kit.ik((0.6, -0.55, 0.45), a), kit.ik((0.6, 0.55, 0.45), b)]
    result = kit.check(scene, [a, *over, b])
    assert result.clear, result.contact
    assert result.pair_checks > 0       # it came near enough to need exact distances


def rack_sweep(kit):
    """Ten waypoints around the base at 0.65 m from its axis: high in front, then down to
    0.25 m from waypoint 6 on, so segment 7 (waypoint 6 -> 7) sweeps into the rack (its top
    at 0.3 m, centred at y = -0.6)."""
    angles = np.radians([30, 20, 0, -20, -40, -55, -70, -90, -110])
    out = [kit.q0]
    for i, t in enumerate(angles):
        out.append(kit.ik((0.65 * np.cos(t), 0.65 * np.sin(t), 0.5 if i < 6 else 0.25),
                          out[-1]))
    return out


def test_a_sweep_through_the_rack_names_the_rack_and_its_segment(kit, scene):
    W = rack_sweep(kit)
    trajectory = kit.plan(W)
    result = check_motion(scene.model(), trajectory.positions, trajectory.dt, trajectory.marks)
    contact = result.contact
    assert contact is not None and contact.bodies[1] == "rack"
    assert contact.segment == 7
    marks = dict((w, s) for s, w in trajectory.marks)
    assert marks[6] < contact.time / trajectory.dt <= marks[7]
    # Up to waypoint 6 the same path is clear.
    assert kit.check(scene, W[:7]).clear


def test_marks_as_a_mapping_and_without_marks(kit, scene):
    a, b = beside_table(kit)
    t = kit.plan([a, b])
    model = scene.model()
    tagged = check_motion(model, t.positions, t.dt, {0: "start", len(t) - 1: "tag 3"})
    assert tagged.contact.segment == "tag 3"
    assert check_motion(model, t.positions, t.dt).contact.segment is None


# ---- parts ------------------------------------------------------------------------------------

def grasp_block_1(kit, scene):
    """Mount the gripper, close it on block_1 (centre 0.15 m below the flange: it pokes 1 cm
    out below the finger tips) and attach it. Returns (grasp joints, joints 18 cm above)."""
    scene.mount_tool("gripper")
    grasp = kit.ik((0.5, -0.15, 0.37))
    above = kit.ik((0.5, -0.15, 0.55), grasp)
    assert kit.check(scene, [above, grasp]).clear     # the open fingers straddle it
    scene.set_finger_gap(0.04)
    scene.attach_part("block_1", q=grasp)
    return grasp, above


def test_a_held_part_lifts_off_and_moves_through_free_space(kit, scene):
    grasp, above = grasp_block_1(kit, scene)
    lift = kit.check(scene, [grasp, above])
    assert lift.clear and lift.started_within == (("block_1", "table"),)
    free = kit.ik((0.6, 0.25, 0.55), above)
    assert kit.check(scene, [above, free]).clear


def test_a_lift_from_contact_is_refused_when_leaving_is_not_allowed(kit, scene):
    grasp, above = grasp_block_1(kit, scene)
    contact = kit.check(scene, [grasp, above], allow_leaving=False).contact
    assert contact.bodies == ("block_1", "table") and contact.time == 0.0


def test_a_held_part_carried_into_the_table_is_refused(kit, scene):
    grasp, above = grasp_block_1(kit, scene)
    into = kit.ik((0.7, 0.1, 0.33), above)      # the part's bottom 4 cm below the table top
    contact = kit.check(scene, [above, into]).contact
    assert contact is not None and contact.bodies == ("block_1", "table")


def test_a_held_part_carried_into_the_rack_is_refused(kit, scene):
    grasp, above = grasp_block_1(kit, scene)
    over_rack = kit.ik((-0.15, -0.6, 0.7), above)
    into = kit.ik((-0.15, -0.6, 0.42), over_rack)   # part bottom 5 cm below the rack top
    contact = kit.check(scene, [above, over_rack, into]).contact
    assert contact is not None and contact.bodies == ("block_1", "rack")
    assert contact.segment == 2


def test_a_part_put_down_is_an_obstacle_where_it_lies(kit, scene):
    grasp, above = grasp_block_1(kit, scene)
    place = kit.ik((0.73, 0.0, 0.37), above)
    pose = scene.release_part(place)
    assert np.allclose(pose[:3, 3], (0.73, 0.0, 0.22), atol=1e-9)
    assert scene.held is None and np.allclose(scene.part_pose("block_1"), pose)
    scene.set_finger_gap(0.08)
    up = kit.ik((0.73, 0.0, 0.55), place)
    assert kit.check(scene, [place, up]).clear
    # A low sweep along the place zone was clear before the part lay there.
    sweep = [kit.ik((0.73, -0.3, 0.33), up), kit.ik((0.73, 0.3, 0.33), up)]
    contact = kit.check(scene, sweep).contact
    assert contact is not None and contact.bodies == ("gripper", "block_1")
    scene.remove_part("block_1")
    assert kit.check(scene, sweep).clear


def test_place_part_moves_an_obstacle(kit, scene):
    a, b = beside_table(kit)
    over = [kit.ik((0.6, -0.55, 0.45), a), kit.ik((0.6, 0.55, 0.45), b)]
    path = [a, *over, b]
    assert kit.check(scene, path).clear
    trajectory = kit.plan(path)
    marks = dict((w, s) for s, w in trajectory.marks)
    middle = trajectory.positions[(marks[1] + marks[2]) // 2]   # halfway along segment 2
    where = kit.kin.forward(middle)[:3, 3]
    scene.place_part("block_2", pose_matrix(where, (0.0, 0.0, 0.3)))
    contact = kit.check(scene, path).contact
    assert contact is not None and contact.bodies[1] == "block_2" and contact.segment == 2


# ---- allowed contacts and exclusions ----------------------------------------------------------

def tool_approach(kit, tool_index: int, height: float):
    """Joints with the flange on tool `tool_index`'s rack slot, and `height` (m) above it."""
    slot = kit.cell.world.tools[tool_index].slot
    at = pose_matrix(slot.xyz, slot.rpy)
    up = at.copy()
    up[2, 3] += height
    q_up = kit.joints(up)
    return kit.joints(at, q_up), q_up


def test_the_bare_flange_docks_on_a_rack_tool_along_its_axis_only(kit, scene):
    """The coupling at the changer: link6 may meet a tool in the rack in the tool's corridor
    (within the changer's 5 mm and 3 degrees of the plate's axis), nowhere else."""
    q_slot, q_up = tool_approach(kit, 0, 0.1)
    assert kit.check(scene, [q_up, q_slot]).clear                 # straight down its axis
    slot = kit.cell.world.tools[0].slot
    at = pose_matrix(slot.xyz, slot.rpy)
    for off in (pose_matrix((0.01, 0, 0), (0, 0, 0)),            # 1 cm beside the axis
                pose_matrix((0, 0, 0), (np.radians(5), 0, 0))):   # tilted 5 degrees
        q_off = kit.joints(at @ off, q_slot)
        contact = kit.check(scene, [kit.joints(at @ off @ pose_matrix((0, 0, -0.1), (0, 0, 0)),
                                               q_off), q_off]).contact
        assert contact.bodies == ("link6", "gripper")
    side = kit.joints(at @ pose_matrix((0.1, 0, -0.003), (0, 0, 0)), q_slot)
    over = kit.joints(at @ pose_matrix((0, 0, -0.003), (0, 0, 0)), q_slot)
    assert kit.check(scene, [side, over]).contact.bodies == ("link6", "gripper")   # a swipe
    # Something left on the tool is still hit.
    scene.place_part("block_2", pose_matrix(np.add(slot.xyz, (0, 0, 0.03)), (0, 0, 0)))
    assert kit.check(scene, [q_up, q_slot]).contact.bodies == ("link6", "block_2")


def test_a_mounted_tool_goes_into_its_own_slot_along_its_axis_only(kit, scene):
    scene.mount_tool("gripper")
    q_slot, q_up = tool_approach(kit, 0, 0.1)
    assert kit.check(scene, [q_up, q_slot]).clear                 # onto the rack, in its slot
    beside = kit.joints(pose_matrix(np.add(kit.cell.world.tools[0].slot.xyz, (0.01, 0, 0)),
                                    kit.cell.world.tools[0].slot.rpy), q_slot)
    assert kit.check(scene, [q_up, beside]).contact.bodies == ("gripper", "rack")
    q_other, _ = tool_approach(kit, 1, 0.05)          # 5 cm above the vacuum cup's slot
    assert kit.check(scene, [q_up, q_other]).contact.bodies == ("gripper", "vacuum")


def test_persistent_allowed_contacts_until_forbidden(kit, scene):
    scene.mount_tool("gripper")
    q_slot, q_up = tool_approach(kit, 0, 0.1)
    beside = kit.joints(pose_matrix(np.add(kit.cell.world.tools[0].slot.xyz, (0.01, 0, 0)),
                                    kit.cell.world.tools[0].slot.rpy), q_slot)
    scene.allow(AllowedContact("set down anywhere", "gripper", "rack"))
    assert kit.check(scene, [q_up, beside]).clear
    scene.forbid("set down anywhere")
    assert not kit.check(scene, [q_up, beside]).clear
    with pytest.raises(CollisionModelError):
        scene.forbid("set down anywhere")


def test_a_gripper_closing_on_its_part_is_allowed_and_hides_nothing_else(kit, scene):
    scene.mount_tool("gripper")
    scene.set_finger_gap(0.03)            # narrower than the block: the fingers land on it
    above = kit.ik((0.5, -0.15, 0.55))
    grasp = kit.ik((0.5, -0.15, 0.37), above)
    assert kit.check(scene, [above, grasp]).contact.bodies == ("gripper", "block_1")
    allowed = [scene.grasp("block_1")]
    assert kit.check(scene, [above, grasp], allow=allowed).clear
    too_low = kit.ik((0.5, -0.15, 0.355), above)      # finger tips 5 mm into the table
    contact = kit.check(scene, [above, too_low], allow=allowed).contact
    assert contact.bodies == ("gripper", "table")


def test_a_guarded_move_excludes_its_surface_and_is_checked_against_the_rest(kit, scene):
    scene.mount_tool("vacuum")
    above = kit.ik((0.65, 0.25, 0.45))
    touch = kit.ik((0.65, 0.25, 0.2 + 0.12 - 0.003), above)   # the cup 3 mm into the table
    assert kit.check(scene, [above, touch]).contact.bodies == ("vacuum", "table")
    assert kit.check(scene, [above, touch], exclude={"table"}).clear
    scene.place_part("block_2", pose_matrix((0.65, 0.25, 0.22), (0, 0, 0)))
    contact = kit.check(scene, [above, touch], exclude={"table"}).contact
    assert contact.bodies == ("vacuum", "block_2")


def test_excluding_the_table_does_not_hide_the_rack(kit, scene):
    contact = kit.check(scene, rack_sweep(kit), exclude={"table"}).contact
    assert contact is not None and contact.bodies[1] == "rack"


def test_unknown_bodies_are_refused(kit, scene):
    a, b = beside_table(kit)
    with pytest.raises(CollisionModelError, match="tabel"):
        kit.check(scene, [a, b], exclude={"tabel"})


# ---- the result and bad input -----------------------------------------------------------------

def test_a_single_configuration_is_checked(kit, scene):
    model = scene.model()
    assert check_motion(model, [kit.q0], 0.004).clear
    inside = kit.ik((0.6, 0.0, 0.15))        # the flange 5 cm deep in the table
    contact = check_motion(model, [inside], 0.004, allow_leaving=False).contact
    assert contact.bodies[1] == "table" and contact.time == 0.0 and contact.fraction == 0.0


def test_a_pair_leaving_may_not_come_closer(kit, scene):
    """Starting within the margin, a pair may move apart, not deeper."""
    scene.mount_tool("vacuum")
    touch = kit.ik((0.65, 0.25, 0.2 + 0.12 + 0.002))          # cup 2 mm above the table
    deeper = kit.ik((0.65, 0.25, 0.2 + 0.12 - 0.002), touch)
    up = kit.ik((0.65, 0.25, 0.4), touch)
    assert kit.check(scene, [touch, up]).clear
    contact = kit.check(scene, [touch, deeper]).contact
    assert contact.bodies == ("vacuum", "table") and contact.distance < 0.001


@pytest.mark.parametrize("positions, dt", [(np.zeros((0, 6)), 0.004), (np.zeros((3, 5)), 0.004),
                                           (np.full((2, 6), np.nan), 0.004),
                                           (np.zeros((2, 6)), 0.0)])
def test_malformed_motions_raise(scene, positions, dt):
    with pytest.raises(ValueError):
        check_motion(scene.model(), positions, dt)


def test_with_every_body_excluded_nothing_is_checked(kit, scene):
    a, b = beside_table(kit)
    model = scene.model()
    result = check_motion(model, [a, b], 0.004, exclude=set(model.bodies()))
    assert result.clear and result.bound_checks == 0 and result.pair_checks == 0


def test_a_clear_result_counts_its_work(kit, scene):
    result = kit.check(scene, [kit.q0, kit.ik((0.4, 0.3, 0.7))])
    assert result.clear and result.bound_checks > 0
    assert result.configurations <= result.pair_checks
