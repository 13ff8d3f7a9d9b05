"""The device server: one robot's LandScape command set over gRPC (`python -m landscape.server`,
app.py puts it together), its command-line settings (config.py), where it listens (listen.py),
log-safe text (log_text.py), one error vocabulary (errors.py) and its child processes' lifeline
(lifeline.py). Its packages follow the processes and the layers:

- api: the gRPC surface (servicers, the guard, conversion, request bounds, stream caps, live
  state streams)
- security: tokens and roles, TLS, the audit log, rate limits (the interceptor)
- device: the state machine, the lock and sessions, power, safety, motion control, settings
- events: the event bus and its records, the alarm codes
- planning: moves, paths, timing (motion/), collision checks (collision/), the planning process
- workcell: the cell's parts (tools, I/O, sensors, guarded moves, jog, vendor commands)
- link: the server's side of the cycle link and the clocks
- cycle: what runs in the cycle process (the Executor and its loops, the feedback ring)

Owns: the device server process and the cycle and planning processes it starts.
May import: landscape.robot, landscape.v1; landscape.sim only by name, through
landscape.robot.backends (the rules: pyproject.toml's import contracts).
"""
