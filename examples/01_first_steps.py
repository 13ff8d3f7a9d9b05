"""First steps: session, lock, activate, move, wait for the done event, read the position,
release.

Start a device server (`make run`), then:  .venv/bin/python examples/01_first_steps.py
"""
import argparse

from landscape.client import DeviceState, Frame, Robot
from landscape.client.values import units_label

parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
parser.add_argument("--target", default="127.0.0.1:50051", help="HOST:PORT of the device server")
args = parser.parse_args()

# A session: the device knows this client while the `with` lasts (keep-alives run behind it).
with Robot(args.target, client_name="first-steps") as robot:
    state = robot.get_device_state()
    print("device state:", DeviceState(state.state).name, "| locked by:",
          state.lock_holder or "nobody")

    # Lock and activate (drives on). Leaving this block, even by an exception, stops any
    # motion, deactivates (drives off) and releases the lock.
    with robot.control():
        # A move is non-blocking: it returns at once with a command id ...
        move = robot.move_absolute([0.5, 0.0, 1.57, 0.0, 1.57, 0.0], Frame.JOINT,
                                   point_name="first-goal", speed=30)
        print("started", move.command_id)
        # ... and its done event follows on the event stream. wait() returns it, or raises
        # CommandFailed with the alarm that says why.
        done = move.wait(timeout=60)
        print("done:", done.event_id, list(done.data))

        position = robot.get_robot_position()
        units = position.units   # every reply with lengths or angles names its units
        print("joints:", [round(q, 4) for q in position.joint_position])
        p = position.world_position
        print(f"tool tip (world): x={p.x:.4f} y={p.y:.4f} z={p.z:.4f} "
              f"roll={p.roll:.4f} pitch={p.pitch:.4f} yaw={p.yaw:.4f} ({units_label(units)})")

    print("released; device state:", DeviceState(robot.get_device_state().state).name)
