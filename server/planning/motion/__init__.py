"""Motion planning for the device server: pure functions and small records, no I/O, no threads.

- trajectory: the records -- Trajectory (what the 4 ms cycle plays), Limits, PlanningError,
  JointPath (the C2 joint spline through waypoints, toppra's path(s, order) protocol).
- timing: time_path, time-optimal timing of a joint path with TOPP-RA, checked per sample
  (sample_check), jerk-limited with jerk_timing's filter and local slow-downs.
- constraints: the bounds TOPP-RA works with (joint and tool speeds, tool accelerations,
  pass speeds); topp_ra: the stage solver, the constant-acceleration profile, toppra as
  reference.
- cartesian: straight lines and arcs of the tool tip as dense joint paths (closed-form IK).

Owns: timing a joint path. Runs in: the device server and the planning process.
May import: the robot's kinematics, numpy; toppra only as a reference, lazily.

Nothing here imports toppra or scipy (toppra alone costs ~2 s to import): topp_ra carries its
own TOPP-RA stage solver and uses the toppra library only as a test/benchmark reference.
"""
from .cartesian import arc, joint_waypoints, straight_line, straight_path, tool_pose
from .timing import time_path
from .trajectory import JointPath, Limits, PlanningError, Reason, Trajectory

__all__ = ["Trajectory", "Limits", "PlanningError", "Reason", "JointPath", "time_path",
           "straight_line", "arc", "straight_path", "joint_waypoints", "tool_pose"]
