"""The dynamics over the oscillator: maps, orbits, continuation, design, simulation.

Layer 2 of 7 (docs/architecture.md). :mod:`.model` is the small protocol (a period map
from a section state with its Jacobian and impact events, the section geometry, the
grazing point) over which :mod:`.shooting` and :mod:`.continuation` are written once;
:mod:`.maps` (the Pi1/Pi2 return maps of the 1-DOF closed form), :mod:`.zdm` (Nordmark's
discontinuity map), :mod:`.orbits` (the 1/1 branch explicit in the impact phase),
:mod:`.perturbation`, :mod:`.design` (c1(c2; delay), lambda0, the admissible set),
:mod:`.fidelity` (the model fidelities), :mod:`.simulate` (event-driven simulation
on Pi2), :mod:`.estimation` (the Pi2 state from a sampled sensor stream: nearest sample,
arc fit, model filter), :mod:`.stream` (which samples make which section; the closed
loop on a stream), :mod:`.noise` (the loop's stationary covariance per unit measurement
noise), :mod:`.tuning` (the least-noise design), :mod:`.mismatch` (model-error bands),
:mod:`.actuation` (a correction as a force pulse), :mod:`.actuator` (a first-order
actuator with latency, exactly), :mod:`.augmented` (the model filter with a sensor bias
and a drifting Delta d), :mod:`.consistency` (the windowed innovation test),
:mod:`.capture` (switching the correction on) and :mod:`.identification` (the model's
parameters from a recorded motion).

May import: :mod:`grazing_control.oscillator`, :mod:`grazing_control.support`. Never rclpy.
"""
