"""Nothing passes between checks: random motions (coarse samples, big joint steps, a tool and a
held part on the flange) checked by check_motion and by brute force, pinocchio's own collision
test at every 0.5 mrad of joint motion along the same linear interpolation."""
from __future__ import annotations

import numpy as np
import pinocchio as pin
import pytest

from landscape.server.planning.collision import CollisionScene, check_motion, clearance
from landscape.robot.units import pose_matrix

MARGIN = 0.005
DENSE_STEP = 5e-4      # rad: the brute force's largest joint step (at most ~0.6 mm of motion)


def dense(Q: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Configurations every DENSE_STEP along the samples Q (N, 6), joints linear between them,
    and their position u in samples (fractional)."""
    out, where = [Q[:1]], [np.zeros(1)]
    for k in range(len(Q) - 1):
        n = max(1, int(np.ceil(np.max(np.abs(Q[k + 1] - Q[k])) / DENSE_STEP)))
        f = np.arange(1, n + 1) / n
        out.append(Q[k] + f[:, None] * (Q[k + 1] - Q[k]))
        where.append(k + f)
    return np.concatenate(out), np.concatenate(where)


def overlapping(model, data, gdata, q) -> bool:
    """Brute force: does any pair overlap at q (security margin 0)?"""
    return pin.computeCollisions(model.pin_model, data, model.geom_model, gdata, q, True)


def nearest(model, q, body: str) -> float:
    """The smallest distance (m) of `body` to anything it is paired with, at q."""
    data, gdata = model.pin_model.createData(), pin.GeometryData(model.geom_model)
    pin.updateGeometryPlacements(model.pin_model, data, model.geom_model, gdata, q)
    return min(pin.computeDistance(model.geom_model, gdata, k).min_distance
               for k, pair in enumerate(model.pair_bodies) if body in pair)


def scenes(kit):
    bare = CollisionScene(kit.cell, MARGIN)
    gripper = CollisionScene(kit.cell, MARGIN)
    gripper.mount_tool("gripper")
    held = CollisionScene(kit.cell, MARGIN)
    held.mount_tool("vacuum")
    held.attach_part("plate_1", in_flange=pose_matrix((0.0, 0.02, 0.125), (0.0, 0.0, 0.4)))
    return {"bare": bare, "gripper": gripper, "held part": held}


def random_motion(kit, model, rng) -> np.ndarray:
    """A start clear by more than the margin, then 1 to 4 random joint moves, sampled with 2 to
    12 samples each (steps of up to ~0.7 rad: far more than the margin between samples)."""
    lo, hi = 0.7 * kit.cell.arm.lower, 0.7 * kit.cell.arm.upper
    while True:
        start = rng.uniform(lo, hi)
        if clearance(model, start).distance > 2 * MARGIN:
            break
    Q = [start[None]]
    for _ in range(rng.integers(1, 5)):
        goal = np.clip(Q[-1][-1] + rng.normal(0.0, 0.8, 6), lo, hi)
        f = np.linspace(0.0, 1.0, rng.integers(2, 13))[1:]
        Q.append(Q[-1][-1] + f[:, None] * (goal - Q[-1][-1]))
    return np.concatenate(Q)


@pytest.mark.parametrize("name", ["bare", "gripper", "held part"])
def test_random_motions_agree_with_a_dense_brute_force(kit, name):
    model = scenes(kit)[name].model()
    data, gdata = model.pin_model.createData(), pin.GeometryData(model.geom_model)
    rng = np.random.default_rng(11)
    seen = {"clear": 0, "contact": 0}
    for _ in range(12):
        Q = random_motion(kit, model, rng)
        result = check_motion(model, Q, 0.004, allow_leaving=False)
        configs, where = dense(Q)
        if result.clear:
            seen["clear"] += 1
            hits = [k for k, q in enumerate(configs) if overlapping(model, data, gdata, q)]
            assert not hits, f"overlap at u = {where[hits[0]]:.3f} missed"
            continue
        seen["contact"] += 1
        contact = result.contact
        # The contact is real: that pair is within the margin at that configuration ...
        pin.updateGeometryPlacements(model.pin_model, data, model.geom_model, gdata, contact.q)
        k = model.pair_bodies.index(contact.bodies)
        pairs = [i for i, b in enumerate(model.pair_shapes) if b == contact.shapes]
        assert pin.computeDistance(model.geom_model, gdata, pairs[0]).min_distance < MARGIN
        assert model.pair_bodies[k] == contact.bodies
        # ... and nothing overlapped before it.
        u = contact.time / 0.004
        before = [q for q, w in zip(configs, where) if w < u]
        assert not any(overlapping(model, data, gdata, q) for q in before)
    assert seen["clear"] and seen["contact"], seen     # both kinds were exercised


def test_a_step_across_a_thin_obstacle_is_caught(kit):
    """Two samples either side of a 1 cm plate: no sample is near it, the motion between is."""
    scene = CollisionScene(kit.cell, MARGIN)
    a, b = kit.ik((0.6, -0.3, 0.45)), kit.ik((0.6, 0.3, 0.45))
    model = scene.model()
    assert check_motion(model, [a, b], 0.004).clear
    middle = kit.kin.forward((a + b) / 2)[:3, 3]
    scene.place_part("plate_1", pose_matrix(middle, (np.pi / 2, 0.0, 0.0)))   # upright
    model = scene.model()
    assert nearest(model, a, "plate_1") > 0.1 and nearest(model, b, "plate_1") > 0.1
    contact = check_motion(model, [a, b], 0.004).contact
    assert contact is not None and contact.bodies[1] == "plate_1"
    assert 0.0 < contact.fraction < 1.0
