"""Two robots at once: two device servers, one asyncio program, both arms moving together.

Each robot has its own device server, as in a cell. A cell file of two arms on this machine
(two.toml; cell/cells/local.toml documents every key):

    [[devices]]
    name = "left"
    port = 50051

    [[devices]]
    name = "right"
    port = 50052

`make run CONFIG=two.toml` starts both (with the CRCL gateway and the web supervisor, which
shows both arms), says where each listens, and stops them safely on Ctrl-C. Then:
    .venv/bin/python examples/04_two_robots.py
"""
import argparse
import asyncio

from landscape.client import AsyncRobot, Frame

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--targets", nargs=2, default=["127.0.0.1:50051", "127.0.0.1:50052"],
                    metavar="HOST:PORT", help="the two device servers")
args = parser.parse_args()

# Each arm waves between two points, mirrored, twice.
WAVE = [[0.6, -0.2, 1.6, 0.0, 1.2, 0.0], [-0.6, -0.2, 1.6, 0.0, 1.2, 0.0]]


async def wave(target: str, name: str, mirrored: bool) -> None:
    async with AsyncRobot(target, client_name=name) as robot:
        async with robot.control():
            for goal in (WAVE[::-1] if mirrored else WAVE) * 2:
                move = await robot.move_absolute(goal, Frame.JOINT, speed=40)
                done = await move.wait(timeout=60)
                print(f"{name}: {done.event_id} {move.command_id} at J1={goal[0]:+.1f}")
        position = await robot.get_robot_position()
        print(f"{name}: released at {[round(q, 3) for q in position.joint_position]}")


async def main() -> None:
    # Both sequences run concurrently; each robot's lock, session and events are its own.
    await asyncio.gather(wave(args.targets[0], "left-robot", False),
                         wave(args.targets[1], "right-robot", True))


asyncio.run(main())
