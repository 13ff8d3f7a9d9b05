"""The simulated controllers, the backends robot/backends.py names: the CS8's side of the LLI
they share (cs8.py, command_checks.py, dio.py, panel.py, recorder.py), the pybullet backend
(bullet_controller.py, bullet_drives.py, world.py, tools.py, sensors.py, native_output.py) and
the kinematic one (kinematic.py: no physics). movegen.py is the LLI sample program's motion
generator, for tests and benchmarks.

Owns: the simulated cell: its physics, its world, its panel.
Runs in: the cycle process (or, on the lock-step clock, a thread of the server).
May import: landscape.robot, numpy, pybullet, mcap, foxglove-sdk (the recorder's schemas);
never landscape.server. Nothing imports it
but by name, through landscape.robot.backends.
"""
