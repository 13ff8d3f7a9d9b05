"""The Foxglove bridge: the cell's arms live in Foxglove, through foxglove-sdk's WebSocket
server (the Foxglove WebSocket protocol) and its well-known schemas (docs/bridges.md).

messages.py turns a device's state samples and events into Foxglove messages; bridge.py is one
device's channels; server.py the WebSocket server, the URDFs it serves and its entry point
(`python -m landscape.bridges.foxglove`).

Owns: what Foxglove shows of a cell; nothing of the device (a watcher, read-only).
Runs in: the Foxglove bridge's process.
May import: landscape.bridges.device_feed, landscape.robot (the arm's links), landscape.client
(credentials), landscape.v1, foxglove-sdk, pinocchio.
"""
