"""Collision checking of planned motions against the cell (issue 11).

- CollisionScene (scene.py): the cell's bodies, following the world (tools mounted, parts held,
  put down, removed; allowed contacts); `scene.model()` compiles the present state.
- CollisionModel (model.py): an immutable compiled snapshot: shapes, pairs, pinocchio/coal.
- check_motion, clearance (check.py): a sampled joint trajectory, or one configuration.

Owns: what may touch what. Runs in: the device server and the planning process.
May import: the robot, motion/, numpy, pinocchio and coal. Nothing here imports pybullet.
"""
from .check import LEAVE_TOLERANCE, CheckResult, Clearance, Contact, check_motion, clearance
from .model import DEFAULT_MARGIN, AllowedContact, CollisionModel, CollisionModelError
from .scene import CollisionScene

__all__ = ["CollisionScene", "CollisionModel", "CollisionModelError", "AllowedContact",
           "DEFAULT_MARGIN", "LEAVE_TOLERANCE", "check_motion", "clearance", "CheckResult",
           "Contact", "Clearance"]
