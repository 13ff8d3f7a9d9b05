"""clearance(q): the smallest distance at one configuration, for scaling jogs near obstacles."""
from __future__ import annotations

import math

import numpy as np
import pinocchio as pin
import pytest

from landscape.server.planning.collision import CollisionModelError, clearance


def brute_force(model, q) -> tuple[float, int]:
    data, gdata = model.pin_model.createData(), pin.GeometryData(model.geom_model)
    pin.computeDistances(model.pin_model, data, model.geom_model, gdata, q)
    d = [r.min_distance for r in gdata.distanceResults]
    return min(d), int(np.argmin(d))


def test_clearance_is_the_smallest_distance_of_all_pairs(scene, kit):
    scene.mount_tool("gripper")
    model = scene.model()
    rng = np.random.default_rng(2)
    for _ in range(40):
        q = rng.uniform(0.6 * model.arm.lower, 0.6 * model.arm.upper)
        found = clearance(model, q)
        d, k = brute_force(model, q)
        assert found.distance == pytest.approx(d, abs=1e-6)
        assert found.bodies == model.pair_bodies[k] or abs(found.distance - d) < 1e-6


def test_clearance_with_a_limit_is_exact_below_it(scene, kit):
    model = scene.model()
    rng = np.random.default_rng(4)
    for _ in range(40):
        q = rng.uniform(0.6 * model.arm.lower, 0.6 * model.arm.upper)
        d, _ = brute_force(model, q)
        found = clearance(model, q, limit=0.05)
        if d < 0.05 - 1e-6:
            assert found.distance == pytest.approx(d, abs=1e-6)
        elif d > 0.05 + 1e-6:
            assert found.distance == math.inf and found.bodies is None


def test_clearance_shrinks_as_the_cup_nears_the_table(scene, kit):
    scene.mount_tool("vacuum")
    model = scene.model()
    last = math.inf
    near = kit.q0
    for gap in (0.015, 0.01, 0.004, 0.001):
        near = kit.ik((0.65, 0.25, 0.2 + 0.12 + gap), near)
        c = clearance(model, near)
        assert c.bodies == ("vacuum", "table")
        assert c.distance == pytest.approx(gap, abs=1e-6) and c.distance < last
        assert c.points[1][2] == pytest.approx(0.2) and c.points[0][2] == pytest.approx(0.2 + gap)
        last = c.distance
    # Excluding the table, the nearest is something else and farther.
    other = clearance(model, near, exclude={"table"})
    assert "table" not in other.bodies and other.distance > last


def test_clearance_refuses_unknown_bodies(scene, kit):
    with pytest.raises(CollisionModelError):
        clearance(scene.model(), kit.q0, exclude={"desk"})
