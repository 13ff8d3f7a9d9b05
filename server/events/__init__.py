"""The device's event stream (DESIGN.md 8): the bus (bus.py: one ordered stream with sequence
numbers, history and per-subscriber buffers), its records (records.py, mirroring
event_service.proto without importing it) and the alarm codes (alarms.py).

Owns: what happened, in order, for every subscriber.
Runs in: the device server.
May import: the server's errors, the standard library; nothing else of landscape.
"""
