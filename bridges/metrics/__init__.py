"""Prometheus's side of every service of a cell: the /metrics endpoint (endpoint.py), with the
process's own figures (memory, CPU, file descriptors).

Owns: where /metrics listens and who may reach it; the metrics of one process each service
counts itself (the device server: server/metrics.py; the gateway and the supervisor: their
metrics.py).
Runs in: the device servers, the CRCL gateway, the web supervisor, the bridges.
May import: prometheus-client, the server's security rule (tls.is_loopback).
"""
