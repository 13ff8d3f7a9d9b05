"""The CRCL gateway: NIST Canonical Robot Command Language clients drive a LandScape device.

CRCL documents arrive on TCP (wire.py), are parsed safely (xmlsafe.py), validated against the
official schemas when configured (schemas.py) and always by the typed parser (parse.py into
model.py), then carried out per connection (session.py) as landscape.v1 calls on a device
server through the client core, landscape.client (device.py: one DeviceLink per gateway, an
AsyncRobot per CRCL session; motions.py, guards.py, tooling.py), in the cell's workstation
frame (workstation.py) and the device's own units (device_units.py); CRCLStatus answers come
from the core's live state feed (live.py, status.py).
"""
