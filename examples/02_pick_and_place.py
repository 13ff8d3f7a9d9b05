"""Pick and place: take the gripper from the rack, move block_1 from the pick zone to the place
zone of the default cell, put the gripper back.

Written against the contract, with the tool commands (GetTool, ActivateTool, DeactivateTool,
PutTool). A server without them stops it at the first one with its UNIMPLEMENTED message
(exit code 2), and the arm is handed back (stopped, drives off, unlocked) as always.

Start a device server (`make run`), then:  .venv/bin/python examples/02_pick_and_place.py
"""
import argparse
import math
import sys

from landscape.client import Frame, Motion, NotImplementedByServer, Pose, Robot

# Where things are in the default cell (robot/cells/default.toml), world frame, meters.
BLOCK = (0.5, -0.15, 0.24)       # top face of block_1 (4 cm cube on the table, top at 0.24)
PLACE = (0.73, -0.15, 0.24)      # the same height in the place zone
GRIPPER_LENGTH = 0.16            # mounting plate to finger tips
CLEARANCE = 0.10                 # approach and retreat height above a grasp
GRASP_DEPTH = 0.02               # fingers close around the upper half of the block
SET_DOWN_GAP = 0.006             # let go this far above the table: closer is a contact the
                                 # collision check refuses (MoveReact touches down instead)
DOWN = (math.pi, 0.0, math.pi)   # roll, pitch, yaw: the tool axis pointing down

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--target", default="127.0.0.1:50051", help="HOST:PORT of the device server")
args = parser.parse_args()


def above(point, height: float) -> list[float]:
    x, y, z = point
    return [x, y, z + height, *DOWN]


def straight_to(robot: Robot, values: list[float], name: str) -> None:
    robot.move_absolute(values, Frame.WORLD, motion=Motion.STRAIGHT, point_name=name,
                        speed=20).wait(timeout=60)


with Robot(args.target, client_name="pick-and-place") as robot, robot.control():
    try:
        # Needs GetTool (seed 3.8.1): the arm fetches the gripper from the rack.
        robot.get_tool("gripper")
        robot.set_tool_offset(Pose(z=GRIPPER_LENGTH))   # moves now place the finger tips
        # Needs DeactivateTool: open the fingers before reaching the block.
        robot.deactivate_tool("gripper")

        robot.move_absolute(above(BLOCK, CLEARANCE), Frame.WORLD, point_name="over-block",
                            speed=30).wait(timeout=60)
        straight_to(robot, above(BLOCK, -GRASP_DEPTH), "grasp")
        robot.activate_tool("gripper")                  # needs ActivateTool: close on the block
        straight_to(robot, above(BLOCK, CLEARANCE), "lift")

        robot.move_absolute(above(PLACE, CLEARANCE), Frame.WORLD, point_name="over-place",
                            speed=30).wait(timeout=60)
        straight_to(robot, above(PLACE, -GRASP_DEPTH + SET_DOWN_GAP), "set-down")
        robot.deactivate_tool("gripper")                # needs DeactivateTool: let go
        straight_to(robot, above(PLACE, CLEARANCE), "retreat")

        robot.put_tool("gripper")                       # needs PutTool: back in the rack
        robot.set_tool_offset(Pose())
        print("block_1 moved to the place zone; gripper back in the rack")
    except NotImplementedByServer as missing:
        print(f"stopped: {missing.message}", file=sys.stderr)
        sys.exit(2)
