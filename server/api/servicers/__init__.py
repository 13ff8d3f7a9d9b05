"""The servicers of the landscape.v1 services, one module per service: look up, convert, call the
device or the cell's part, wrap the result (STYLE 2). Every RPC passes the guard (../guard.py).

Owns: the RPC bodies.
Runs in: the device server, on its event loop and the guard's thread pools.
May import: the rest of landscape.server.api, the device, the workcell, planning's records,
events, the robot, landscape.v1. Nothing imports a servicer but server/app.py.
"""
