"""Teach and replay: visit a few points, record where the arm is at each, save them as a path
file, then load that file as a named path and replay it, following its tags.

Teaching here moves the arm to each point by command. An operator may jog it there instead,
under manual control (robot.manual_control(TEACHPENDANT), then robot.jog(...); or the web
supervisor's jog pendant and its "Teach current pose" button); the recording is the same: the
measured position (GetRobotPosition) becomes a tagged point.

Start a device server (`make run`), then:
    .venv/bin/python examples/03_teach_and_replay.py --file taught.json
and replay the file again later with the CLI:  landscape path run taught --file taught.json
"""
import argparse
import contextlib

from landscape.client import Frame, Robot, TagPoint
from landscape.client.errors import NotFound
from landscape.client.pathfile import read_path, write_path

# Where the "operator" takes the arm (joints, radians), with the names the tags will carry.
TEACH = {
    "approach": [0.3, -0.2, 1.7, 0.0, 1.1, 0.0],
    "left": [0.6, 0.1, 1.4, 0.0, 1.2, 0.3],
    "right": [-0.2, 0.1, 1.4, 0.0, 1.2, -0.3],
    "home": [0.0, 0.0, 1.5708, 0.0, 1.5708, 0.0],
}

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--target", default="127.0.0.1:50051", help="HOST:PORT of the device server")
parser.add_argument("--file", default="taught.json", help="where to save the taught path")
parser.add_argument("--cycles", type=int, default=2, help="how many times to replay it")
args = parser.parse_args()

with Robot(args.target, client_name="teacher") as robot, robot.control():
    # Teach: go to each point, then record the measured joints as a tagged point.
    taught = []
    for name, joints in TEACH.items():
        robot.move_absolute(joints, Frame.JOINT, point_name=name, speed=40).wait(timeout=60)
        measured = list(robot.get_robot_position().joint_position)
        taught.append(TagPoint(measured, tag_name=name, time_delay=0.2))
        print(f"taught {name}: {[round(q, 4) for q in measured]}")
    write_path(args.file, frame="joint", motion="joint", points=taught)
    print(f"saved {len(taught)} points to {args.file}")

    # Replay: read the file back, load it as a named path (replacing an older one), run it.
    path = read_path(args.file)
    name = "taught"
    with contextlib.suppress(NotFound):   # the first time there is none
        robot.path_clear_path(name)
    robot.path_load(name, path.points, path.frame, motion=path.motion)
    run = robot.path_move(name, number_of_cycles=args.cycles)
    for event in run.follow(timeout=120):
        if event.event_id == "tag_reached":
            print(f"  reached {event.command.tag_name}")
    print(f"replayed {name} {args.cycles} times ({run.command_id} done)")
