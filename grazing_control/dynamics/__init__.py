"""The dynamics over the oscillator, in six folders.

Layer 2 of 7 (docs/architecture.md, where each module is listed).

* :mod:`.maps`: maps and local theory: the Pi1/Pi2 return maps of the 1-DOF closed form,
  the small model protocol (:class:`.maps.model.PeriodMap`: a period map from a section
  state with its Jacobian and impact events, the section geometry, the grazing point),
  Nordmark's discontinuity map, perturbation estimates, the compliant and n-DOF models.
* :mod:`.orbits`: orbits, shooting and continuation (written once over the protocol), the
  1/1 branch explicit in the impact phase, two-parameter continuation.
* :mod:`.design`: design and tuning: c1(c2; delay), the admissible set, the least-noise c2,
  model-error bands, the least spectral radius, switching on; the n-DOF design.
* :mod:`.estimation`: the Pi2 state from a sampled sensor stream, the stream's sections,
  the watchful filter (bias, drift), its consistency test and the refit in the loop (its
  fit imported where it runs: a node does not load the solver), the rig's clock.
* :mod:`.identification`: the model's parameters from a recorded motion, the stop the data
  support.
* :mod:`.simulation`: event-driven simulation on Pi2, pulses and actuators, fidelities,
  Lyapunov exponents.

May import: :mod:`grazing_control.oscillator`, :mod:`grazing_control.support`. Never rclpy.
"""
