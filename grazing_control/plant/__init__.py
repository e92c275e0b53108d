"""The plant emulator: what sim_node drives, without ROS.

Layer 3 of 7 (docs/architecture.md). :mod:`.settings` (the simulator's validated
parameters), :mod:`.engine` (samples and periods of the exact oscillator, corrections
applied on schedule or on arrival), :mod:`.realtime` (pacing, deadlines and the
bookkeeping of answers in realtime mode) and :mod:`.faults` (injected loss,
measurement noise and jitter, a pure function of seed and sample).

May import: :mod:`grazing_control.dynamics` and below. Never rclpy: the node adapter
(sim_node) translates between this and ROS.
"""
