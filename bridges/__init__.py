"""The bridges to the tools a cell's users already run (docs/bridges.md): Foxglove (foxglove/:
the live WebSocket server), Prometheus (metrics/: the /metrics endpoint every service serves)
and OPC UA (opcua/: the cell as OPC 40010 models a motion device system).

Owns: what the cell says to Foxglove, Prometheus and OPC UA clients; nothing of the device.
Runs in: the bridges' own processes (Foxglove, OPC UA: clients of the device servers' state
and event streams, like the web supervisor), and metrics/ in every service.
May import: landscape.client (credentials, identity), landscape.robot (the arm, its links),
landscape.v1, the server's security rule (tls.is_loopback), foxglove-sdk, prometheus-client,
asyncua; never the device server's inside nor the simulator.
"""
