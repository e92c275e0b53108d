"""The plant emulator: what sim_node drives, without ROS.

Layer 3 of 7 (docs/architecture.md). :mod:`.settings` (the simulator's parameter table
and its validation), :mod:`.engine` (samples and periods of the exact oscillator,
corrections on schedule, delayed or on arrival, the events to publish), :mod:`.loop`,
:mod:`.lockstep` and :mod:`.realtime` (the two ways the node runs the engine: one period
per answer, or paced to a wall clock with deadlines), :mod:`.faults` (injected loss,
measurement noise and jitter, a pure function of seed and sample) and :mod:`.sensor`
(the rig's motion sensor: noise, bias, quantisation, position only). The actuator's
force pulse is :mod:`grazing_control.dynamics.simulation.actuation`. An n-DOF model file
(issue 32) runs on the same settings and engine; its model-specific pieces are the
model's (:mod:`grazing_control.oscillator.ndof.section`).

May import: :mod:`grazing_control.dynamics` and below. Never rclpy: the node adapter
(sim_node) translates between this and ROS.
"""
