"""The OPC UA bridge: a cell's arms for a plant's MES and SCADA, as OPC 40010 (Robotics)
models a motion device system (model.py), served by asyncua (server.py; `python -m
landscape.bridges.opcua`). Read-only; anonymous on loopback only.

Owns: what OPC UA clients see of a cell; nothing of the device (a watcher, read-only).
Runs in: the OPC UA bridge's process.
May import: landscape.bridges.device_feed, landscape.client (credentials), landscape.v1,
the server's security rule (tls.is_loopback), asyncua.
"""
