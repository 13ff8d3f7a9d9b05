"""What runs in the cycle process, every 4 ms (DESIGN.md 7): the device's cyclic function
(executor.py) with its loops (playback.py: trajectories, ramps.py: their jerk-limited stop and
resume ramps; force_loops.py: guarded and compliant motion; jog_integrator.py: jog and its
deadman; jerk_tracker.py: the jerk-limited last stage of jog and the force loops; inputs.py:
sensors, the I/O image and watches), the model torques and tip Jacobians (arm_dynamics.py,
tip_model.py), the feedback ring it writes (feedback.py), the trajectories it reads
(run_arrays.py, shared_array.py), the controller it steps (factory.py: the cell's backend), and
the process itself (process.py: its protocol and loop; child.py: its entry; stats.py: its
timing).

Owns: the per-cycle part of the device, and the wire between the cycle and the server.
Runs in: the cycle process (or, on the lock-step clock, a thread of the server).
May import: landscape.robot, landscape.server.lifeline, numpy, pinocchio, ruckig; nothing of
the gRPC surface, nor grpc, nor the device (the server reads what it writes).
"""
