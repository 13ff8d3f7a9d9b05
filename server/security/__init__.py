"""Security (docs/security.md): role tokens and the role each RPC needs (auth.py), TLS and the
exposure rule (tls.py), the audit log (audit.py, audit_file.py), rate limits and refusal tallies
(rate_limit.py, refusal_tally.py), and the interceptor that applies them (interceptor.py).

Owns: who may call what, and the record of who did.
Runs in: the device server (auth.py and tls.py are also read by the gateway, the web supervisor
and the launcher).
May import: the device's state table, the server's errors and log text, api's guard and stream
caps, landscape.v1, grpc.
"""
