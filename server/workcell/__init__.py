"""The cell's parts, as the device's commands reach them (seed 3.7, 3.8, 4): tools and the tool
changer (tooling.py), digital I/O (digital_io.py), sensors (sensing.py), guarded and compliant
motion (guarded.py), manual control and jog with its clearance guard (jog.py, jog_guard.py),
the vendor hook (vendor.py), the loose parts the collision scene follows (world_parts.py), and
their assembly (assembly.py). Each is given the parts of the device it uses, never the Device.

Owns: the server side of the cell's parts (their per-cycle loops are the cycle package's).
Runs in: the device server.
May import: the device, planning, events, the link, the cycle's records and specs, the robot,
the server's errors; never the gRPC surface.
"""
