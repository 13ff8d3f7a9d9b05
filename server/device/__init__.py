"""The device (DESIGN.md 4, 5): the state machine, the one owner of the state, the lock holder,
the lease, the epoch, power, e-stop and error (state_machine.py, the table of states.py), the
sessions and their keep-alives (sessions.py), RSVP questions (rsvp.py), the drives (power.py),
the safety actions and their worker (safety.py), motion control from plan to cycle and back
(motion_control.py), the named paths and their runs (path_runs.py), the motion settings and
their storage (motion_settings.py, stored_settings.py), and the Device that puts them
together (device.py).

Owns: every change of the device's state; nothing else changes it.
Runs in: the device server.
May import: planning, events, the link, the cycle's feedback and run arrays, the robot, the
server's errors and config; never the gRPC surface.
"""
