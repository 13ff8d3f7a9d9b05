"""The gRPC surface: the servicers of the landscape.v1 services (servicers/, thin: convert, call
the device, wrap), the guard every RPC passes (guard.py: request bounds, the state table, the
lease, where a body runs, one error mapping), all proto <-> domain conversion, units included
(convert.py), the bounds on what a request may carry (request_bounds.py), the streams a client
may hold (stream_caps.py), live state per watcher (state_stream.py), the cell's description
(cell_view.py), the services' table and reflection (services.py, reflection_pool.py).

Owns: everything that knows protobuf messages and gRPC contexts.
Runs in: the device server (the planning process parses PathLoad messages with convert.py).
May import: the device, the workcell, planning, events, security's roles, the link, the cycle's
feedback, the robot, landscape.v1, grpc. Only server/app.py imports a servicer.
"""
