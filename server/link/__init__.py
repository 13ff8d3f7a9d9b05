"""The server's side of the cycle link (DESIGN.md 7): the controller on one of three clocks
(controller_link.py: its feedback, messages to the cycle, calls between cycles, a watch on its
life), the clocks (clock.py: lock-step; realtime_clock.py: the cycle process's parent side)
and the controller's asynchronous LLI calls across the process boundary (controller_proxy.py).

Owns: the cycle process's life and the lines to it.
Runs in: the device server.
May import: the cycle package, the robot, the server's config and errors; never the device,
the servicers or the cell's parts (they are given the link).
"""
