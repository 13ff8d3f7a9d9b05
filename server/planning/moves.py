"""From a move request to a timed trajectory: the device's use of the motion library."""
from __future__ import annotations

import math

import numpy as np

from landscape.server.errors import OutOfRange, ParamError, Unreachable
from landscape.server.planning.joint_line import time_joint_line
from landscape.server.planning.motion.cartesian import MAX_SAMPLES, arc, circle, straight_line, tool_pose
from landscape.server.planning.motion.stretch_timing import time_in_stretches
from landscape.server.planning.motion.timing import duration_lower_bound, time_path
from landscape.server.planning.motion.trajectory import Limits, PlanningError, Reason, Trajectory
from landscape.server.device.motion_settings import MAX_MOTION_SECONDS, MIN_PERCENT, MotionSettings
from landscape.server.planning.targets import (Frame, check_joints, check_pose_values, check_reach,
                                     goal_tip, reach)
from landscape.robot.kinematics import Config, Kinematics, PosNeg, Shoulder

SAME_CONFIG = Config(Shoulder.SAME, PosNeg.SAME, PosNeg.SAME)


class Planner:
    """Plans the device's moves; stateless apart from the arm and the cycle time."""

    def __init__(self, kinematics: Kinematics, cycle_time: float):
        self.kinematics = kinematics
        self.arm = kinematics.arm
        self.dt = cycle_time

    def limits(self, settings: MotionSettings, speed_percent: float | None) -> Limits:
        speed = settings.speed_percent if speed_percent is None else speed_percent
        if not math.isfinite(speed):
            raise ParamError(f"move speed must be a finite number, got {speed}")
        if not MIN_PERCENT <= speed <= 100:
            raise OutOfRange(f"move speed must be at least {MIN_PERCENT:g} % and at most 100 %, "
                             f"got {speed:g} %", field="speed", minimum=f"{MIN_PERCENT:g} %",
                             maximum="100 %")
        # Seed 3.2.1: the percents apply to joint and Cartesian moves alike; the absolute
        # Cartesian speeds and accelerations are caps of their own, not scaled by them.
        return Limits.scaled(self.arm, speed, settings.accel_percent,
                             settings.linear_speed, settings.angular_speed,
                             settings.linear_accel, settings.angular_accel)

    def move(self, q_now, settings: MotionSettings, frame: Frame, values: np.ndarray,
             relative: bool, straight: bool, speed_percent: float | None) -> Trajectory:
        """Seed 3.4.1 moveAbsolute / moveRelative from q_now (rad); values in SI (joints rad;
        x, y, z m and roll, pitch, yaw rad). The tool tip goes straight, or the joints
        interpolate."""
        limits = self.limits(settings, speed_percent)
        tcp = settings.tool_offset
        if frame is Frame.JOINT:
            goal_q = check_joints(self.arm, q_now + values if relative else values)
            tip_goal = self.kinematics.forward(goal_q) @ tcp
        else:
            tip_now = self.kinematics.forward(q_now) @ tcp
            tip_goal = goal_tip(frame, check_pose_values(values), relative, tip_now, settings)
        if straight:
            check_reach(self.arm, tip_goal @ np.linalg.inv(tcp), "values")
            return self.straight_move(q_now, tip_goal, limits, tcp)
        if frame is not Frame.JOINT:
            goal_q = self.pose_goal_joints(q_now, tip_goal @ np.linalg.inv(tcp))
        return self.joint_move(q_now, goal_q, limits)

    def arc(self, q_now, settings: MotionSettings, frame: Frame, via: np.ndarray,
            goal: np.ndarray, relative: bool, speed_percent: float | None) -> Trajectory:
        """Seed 3.4.1 moveArc: JOINT_FRAME points are taken through forward kinematics;
        relative points are offsets from where the tip is now."""
        limits = self.limits(settings, speed_percent)
        tcp = settings.tool_offset
        tip_now = self.kinematics.forward(q_now) @ tcp
        if frame is Frame.JOINT:
            tips = [self.kinematics.forward(check_joints(self.arm, q_now + v if relative else v))
                    @ tcp for v in (via, goal)]
        else:
            tips = [goal_tip(frame, check_pose_values(v, field), relative, tip_now, settings)
                    for v, field in ((via, "arc_value"), (goal, "goal_value"))]
        inv_tcp = np.linalg.inv(tcp)
        for tip, field in zip(tips, ("arc_value", "goal_value")):
            check_reach(self.arm, tip @ inv_tcp, field)
        self.check_arc_reach(tip_now, tips[0], tips[1], tcp)
        return self.arc_move(q_now, tips[0], tips[1], limits, tcp)

    def check_arc_reach(self, tip_now, tip_via, tip_goal, tcp) -> None:
        """Unreachable naming arc_value if the arc is longer than any arc within the tip's
        reach (2 pi times its radius): nearly collinear points with the arc point beyond the
        goal make a huge circle, which no sampling should attempt."""
        try:
            _, radius, _, _, sweep = circle(tip_now[:3, 3], tip_via[:3, 3], tip_goal[:3, 3])
        except PlanningError as error:
            raise _unreachable(error) from None
        longest = 2.0 * math.pi * (reach(self.arm)[1] + float(np.linalg.norm(tcp[:3, 3])))
        if radius * sweep > longest:
            raise Unreachable(f"arc_value: the arc through it is not reachable: it is "
                              f"{radius * sweep:.4g} m long, and an arc within the arm's reach "
                              f"is at most {longest:.4g} m long", reason_code="OUT_OF_WORKSPACE",
                              field="arc_value", maximum=f"{longest:.4g} m")

    def joint_move(self, q_now, q_goal, limits: Limits,
                   max_duration: float = MAX_MOTION_SECONDS) -> Trajectory:
        """The straight joint-space line to q_goal within max_duration (s): ruckig's
        jerk-limited optimum (joint_line.py), or time_path where that does not apply."""
        waypoints = np.array([q_now, check_joints(self.arm, q_goal)])
        check_duration(waypoints, limits, max_duration)
        try:
            line = time_joint_line(waypoints[0], waypoints[1], limits, self.dt, max_duration)
        except PlanningError as error:
            raise _unreachable(error) from None
        return line if line is not None else self.timed(waypoints, limits,
                                                        max_duration=max_duration)

    def pose_goal_joints(self, q_now, flange_goal: np.ndarray, field: str = "values"
                         ) -> np.ndarray:
        """Joints reaching `flange_goal` in q_now's configuration, nearest q_now; a goal beyond
        reach is Unreachable naming the request's `field`."""
        check_reach(self.arm, flange_goal, field)
        q, result = self.kinematics.reverse(flange_goal, q_now, SAME_CONFIG)
        if q is None:
            raise Unreachable(f"the target pose is not reachable: {result.name}",
                              reason_code=result.name)
        return q

    def straight_move(self, q_now, tip_goal: np.ndarray, limits: Limits,
                      tool_offset: np.ndarray) -> Trajectory:
        """The tool tip (flange @ tool_offset) on a straight line to `tip_goal`."""
        try:
            path = straight_line(self.kinematics, q_now, tip_goal, tcp=tool_offset)
        except PlanningError as error:
            raise _unreachable(error) from None
        return self.timed(path, limits, tool_pose(self.kinematics, tool_offset))

    def arc_move(self, q_now, tip_via: np.ndarray, tip_goal: np.ndarray, limits: Limits,
                 tool_offset: np.ndarray) -> Trajectory:
        """The tool tip on the circle through its position, `tip_via` and `tip_goal`."""
        try:
            path = arc(self.kinematics, q_now, tip_via, tip_goal, tcp=tool_offset)
        except PlanningError as error:
            raise _unreachable(error) from None
        return self.timed(path, limits, tool_pose(self.kinematics, tool_offset))

    def timed(self, waypoints: np.ndarray, limits: Limits, tool_path=None, *, stops=None,
              max_duration: float = MAX_MOTION_SECONDS,
              pass_speeds: dict[int, float] | None = None) -> Trajectory:
        """time_path, refused before any planning if it cannot end within max_duration (s),
        and bounded by it while it plans."""
        check_duration(waypoints, limits, max_duration, stops, tool_path)
        try:
            return time_path(waypoints, limits, self.dt, stops=stops, tool_path=tool_path,
                             max_duration=max_duration, pass_speeds=pass_speeds)
        except PlanningError as error:
            raise _unreachable(error) from None

    def timed_in_stretches(self, waypoints: np.ndarray, limits: Limits, tool_path=None, *,
                           pass_speeds: dict[int, float] | None = None):
        """time_in_stretches of one section (at rest at its ends only), its chunks as they are
        timed; refused as `timed` before any planning if it cannot end within
        MAX_MOTION_SECONDS, and raising as it does from a later chunk."""
        check_duration(waypoints, limits, MAX_MOTION_SECONDS, None, tool_path)
        return _refused_as_commands(time_in_stretches(waypoints, limits, self.dt,
                                                      tool_path=tool_path,
                                                      pass_speeds=pass_speeds))


def _refused_as_commands(chunks):
    try:
        yield from chunks
    except PlanningError as error:
        raise _unreachable(error) from None


def check_duration(waypoints: np.ndarray, limits: Limits, max_duration: float, stops=None,
                   tool_path=None, before: float = 0.0) -> None:
    """OutOfRange naming the speed or the acceleration if the motion through `waypoints`, after
    `before` s of other motion, cannot end within max_duration (s), by a cheap lower bound."""
    least, what = duration_lower_bound(waypoints, limits, stops, tool_path)
    if before + least > max_duration:
        raise OutOfRange(f"the motion would last at least {before + least:.4g} s at the set "
                         f"{what}; a motion lasts at most {MAX_MOTION_SECONDS:g} s",
                         field=what, maximum=f"{MAX_MOTION_SECONDS:g} s")


def _unreachable(error: PlanningError) -> OutOfRange:
    if error.reason is Reason.TOO_LONG:
        return OutOfRange(f"{error}; a motion lasts at most {MAX_MOTION_SECONDS:g} s",
                          field="duration", maximum=f"{MAX_MOTION_SECONDS:g} s")
    if error.reason is Reason.TOO_MANY_SAMPLES:
        return OutOfRange(str(error), field="path", maximum=f"{MAX_SAMPLES} samples")
    where = {}
    if error.index is not None:
        where["index"] = str(error.index)
    if error.fraction is not None:
        where["fraction"] = f"{error.fraction:.4f}"
    return Unreachable(str(error), reason_code=error.reason, **where)

