"""Robustness of the discrete grazing controller (issue 8 sections 1 and 3).

* :mod:`.delay`: the controlled 1/1 orbit's largest multiplier when the actual
  actuation delay differs from the one the gains were designed for, the stability
  interval of the delay, and stability maps over (c2, delay) (docs/theory_delay.md,
  section 6).
* :mod:`.faults`: the closed loop through the exact core with lost corrections,
  measurement noise and delay jitter (:class:`grazing_control.plant.faults.FaultModel`):
  capture probability and stationary spread (docs/robustness.md).
* :mod:`.charts`: the charts of both, and :mod:`.cli` the ``grazing robustness``
  command that makes them.
"""
