"""The compiled model: the shapes the cell file and the URDFs give, the pairs checked and left
out, and the broad phase's bounds (they must hold for every configuration)."""
from __future__ import annotations

from importlib import resources

import coal
import numpy as np
import pinocchio as pin
import pytest

from landscape.server.planning.collision import (DEFAULT_MARGIN, CollisionModelError, CollisionScene,
                                        check_motion)
from landscape.server.planning.collision.distance_bounds import SphereCentres, joint_travel, lower_bounds
from landscape.server.planning.collision.shapes import ARM_LINKS, FLOOR
from landscape.robot.units import pose_matrix
from landscape.robot.cell import parse_cell


def test_the_default_cell_has_every_body(scene, kit):
    model = scene.model()
    world = kit.cell.world
    expected = (list(ARM_LINKS) + [f.name for f in world.fixtures] + [t.name for t in world.tools]
                + [p.name for p in world.parts] + [FLOOR])
    assert model.bodies() == tuple(expected)
    assert model.margin == DEFAULT_MARGIN
    # Fixed bodies are never paired with each other; base_link only with moving links.
    fixed = ({"base_link", FLOOR} | {f.name for f in world.fixtures}
             | {t.name for t in world.tools} | {p.name for p in world.parts})
    assert not [p for p in model.pair_bodies if set(p) <= fixed]
    for a, b in model.pair_bodies:
        assert a in ARM_LINKS[1:]


def test_adjacent_and_overlapping_links_are_not_paired(scene):
    bodies = {frozenset(p) for p in scene.model().pair_bodies}
    for a, b in zip(ARM_LINKS, ARM_LINKS[1:]):
        assert frozenset((a, b)) not in bodies
    # The upper arm and forearm cylinders overlap at the elbow at q = 0: not a collision.
    assert frozenset(("link2", "link4")) not in bodies
    assert frozenset(("link2", "link5")) in bodies and frozenset(("link1", "link4")) in bodies


def test_a_mounted_tool_is_paired_with_the_arm_but_not_with_the_flange(scene):
    scene.mount_tool("gripper")
    bodies = {frozenset(p) for p in scene.model().pair_bodies}
    assert frozenset(("link4", "gripper")) in bodies and frozenset(("gripper", "table")) in bodies
    assert frozenset(("link6", "gripper")) not in bodies
    # link5 turns about J6 around the tool: they never come within the margin.
    assert frozenset(("link5", "gripper")) not in bodies


def test_a_held_part_reaching_link5_stays_paired(scene, kit):
    """A part held against the wrist is not dropped as 'never close' to link5."""
    scene.attach_part("block_1", in_flange=pose_matrix((0.0, 0.0, -0.045), (0, 0, 0)))
    model = scene.model()
    assert ("link5", "block_1") in model.pair_bodies
    contact = check_motion(model, [kit.q0], 0.004, allow_leaving=False).contact
    assert contact.bodies == ("link5", "block_1")


def test_geometry_follows_the_link_frames_and_the_base(kit):
    toml = resources.files("landscape.robot").joinpath("cells/default.toml").read_text()
    moved = parse_cell(toml.replace("base_xyz = [0.0, 0.0, 0.0]", "base_xyz = [0.0, 0.0, 0.1]")
                       .replace("base_rpy_deg = [0.0, 0.0, 0.0]",
                                "base_rpy_deg = [0.0, 0.0, 30.0]"))
    scene = CollisionScene(moved)
    model = scene.model()
    q = np.array([0.3, -0.2, 1.2, 0.4, 0.8, -0.5])
    frames = model.kinematics.link_frames(q)
    data = model.pin_model.createData()
    pin.forwardKinematics(model.pin_model, data, q)
    for i in range(6):
        assert np.allclose(frames[i], data.oMi[i + 1].homogeneous, atol=1e-12)
    # The table, in base_link, is where the cell puts it in the world.
    table = next(g for g in model.geometries if g.body == "table")
    assert np.allclose(model.to_world(table.placement[:3, 3]), (0.6, 0.0, 0.1), atol=1e-12)
    assert np.allclose(model.to_world(np.zeros(3)), (0.0, 0.0, 0.1))


def distances_to_probes(model, gdata, index: int, probes: np.ndarray) -> np.ndarray:
    """(K,) m: the distance of shape `index`, where gdata places it, to points probes (K, 3)."""
    g = model.geometries[index]
    T = gdata.oMg[index].homogeneous
    shape_at = coal.Transform3s(T[:3, :3], T[:3, 3])
    point = coal.Sphere(1e-6)
    out = []
    for p in probes:
        result = coal.DistanceResult()
        out.append(coal.distance(g.shape, shape_at, point, coal.Transform3s(np.eye(3), p),
                                 coal.DistanceRequest(), result))
    return np.array(out)


def test_the_motion_bound_holds_for_random_steps(scene):
    """No moving shape's distance to anything changes by more than its levers say, along
    random straight joint steps (checked half way and at the end): fixed probe points all
    around stand for the obstacles."""
    scene.mount_tool("gripper")
    scene.attach_part("block_1", in_flange=pose_matrix((0.0, 0.0, 0.15), (0, 0, 0.2)))
    model = scene.model()
    data, gdata = model.pin_model.createData(), pin.GeometryData(model.geom_model)
    moving = [i for i, g in enumerate(model.geometries) if g.link > 0]
    rng = np.random.default_rng(3)
    for _ in range(60):
        q = rng.uniform(model.arm.lower, model.arm.upper)
        dq = rng.normal(0.0, 0.3, 6) * (rng.random(6) < 0.6)
        probes = rng.uniform(-1.3, 1.3, (8, 3)) + (0, 0, 0.5)
        pin.updateGeometryPlacements(model.pin_model, data, model.geom_model, gdata, q)
        before = [distances_to_probes(model, gdata, i, probes) for i in moving]
        for f in (0.5, 1.0):
            pin.updateGeometryPlacements(model.pin_model, data, model.geom_model, gdata,
                                         q + f * dq)
            for k, i in enumerate(moving):
                change = np.abs(distances_to_probes(model, gdata, i, probes) - before[k]).max()
                assert change <= model.bounds.lever[k] @ np.abs(f * dq) + 1e-6


def test_pair_distances_change_no_more_than_their_levers(scene):
    """Between two moving shapes (and against the round base column) only the joints between
    them count, and a joint about which the nearer shape is round counts for nothing."""
    scene.mount_tool("gripper")
    model = scene.model()
    data, gdata = model.pin_model.createData(), pin.GeometryData(model.geom_model)
    rng = np.random.default_rng(8)

    def distances(q):
        pin.computeDistances(model.pin_model, data, model.geom_model, gdata, q)
        return np.array([r.min_distance for r in gdata.distanceResults])

    for _ in range(80):
        q = rng.uniform(model.arm.lower, model.arm.upper)
        dq = rng.normal(0.0, 0.3, 6)
        before, after = distances(q), distances(q + dq)
        apart = (before > 0) & (after > 0)
        limit = model.pair_table.lever @ np.abs(dq)
        assert np.all(np.abs(after - before)[apart] <= limit[apart] + 1e-6)


def test_round_shapes_do_not_move_when_they_turn_about_their_axis(scene):
    """link1 (about J1), link4 (J4) and link6 (J6) are cylinders on their joint's axis; the base
    column is round about J1, link3 about J4 and link5 about J6."""
    b = scene.model().bounds
    own = {link: b.lever[k, link - 1] for k, link in enumerate(b.link)}
    assert own[1] == own[4] == own[6] == 0.0 and own[2] > 0 and own[3] > 0 and own[5] > 0
    assert b.round_next.tolist() == [False, False, True, False, True, False]
    assert b.box_round_next[0]        # base_link, the first fixed shape


def test_the_pair_bounds_are_below_the_distances(scene):
    scene.mount_tool("gripper")
    model = scene.model()
    data, gdata = model.pin_model.createData(), pin.GeometryData(model.geom_model)
    rng = np.random.default_rng(5)
    Q = rng.uniform(0.8 * model.arm.lower, 0.8 * model.arm.upper, (60, 6))
    centres = SphereCentres(model.bounds, model.kinematics, Q)
    pairs = np.arange(len(model.pairs))
    for k, q in enumerate(Q):
        bound = lower_bounds(model.bounds, model.pair_table,
                             centres.ensure(np.full(len(pairs), k)), pairs,
                             np.full(len(pairs), k))
        pin.computeDistances(model.pin_model, data, model.geom_model, gdata, q)
        distance = np.array([r.min_distance for r in gdata.distanceResults])
        # Bounds hold for separations (an overlap's depth is another matter).
        apart = distance > 0
        assert np.all(bound[apart] <= distance[apart] + 1e-9)


def test_joint_travel_adds_absolute_steps():
    q = np.array([[0.0] * 6, [0.5, -0.5, 0, 0, 0, 0], [0.2, 0.5, 0, 0, 0, 1.0]])
    assert np.allclose(joint_travel(q)[-1], [0.8, 1.5, 0, 0, 0, 1.0])


def test_a_margin_must_be_positive(kit):
    with pytest.raises(CollisionModelError):
        CollisionScene(kit.cell, margin=0.0)
