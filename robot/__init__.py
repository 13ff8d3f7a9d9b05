"""The robot, as every process of a device sees it: the TX90-class arm (arm.py: its published
figures and URDF), its kinematics (kinematics.py, kinematics_batch.py: forward, closed-form
inverse, the LLI configurations), pinocchio's model of it (pinocchio_model.py), units and poses
(units.py), every link in its parent for viewers (link_frames.py: Foxglove's FrameTransforms),
the controller interface shaped like the Staubli LLI with its optional
capabilities (controller.py), the backends' table (backends.py), and the cell file (cell.py,
cell_model.py, toml_tables.py, tool_shapes.py; the shipped worlds in cells/).

Owns: what the server, the cycle process and every backend must agree on.
Runs in: every process (the server, the cycle process, the planning process, the launcher).
May import: numpy, pinocchio, pydantic, foxglove-sdk's messages (link_frames.py, when used)
and itself; never landscape.server nor landscape.sim
(a backend is found by name, backends.py).
"""
