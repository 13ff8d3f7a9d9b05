"""Planning (DESIGN.md 6): from a request to a timed, checked trajectory. Moves (moves.py),
targets and frames (targets.py), paths and their library in SQLite (paths.py, path_planning.py,
aux_commands.py, sqlite_file.py), timing (motion/: TOPP-RA), collision checks (collision/), and
the planning process that resolves, times and checks long paths beside a cycle process
(process.py).

Owns: what a motion will be before anything moves.
Runs in: the device server, and the planning process.
May import: the robot, the device's settings, events' records, the server's errors,
landscape.server.lifeline, and api/convert.py for the PathLoad messages the planning process
parses.
"""
