"""The 1/1 orbit near grazing of a model file's model (any n; issue 17), each orbit by the
one entry of the 1/1 orbit for every model (:mod:`grazing_control.dynamics.orbits.one_one`;
docs/ndof_commands.md):

* :mod:`.scaling`: the orbit's multipliers on a log grid of Delta d and the fitted
  growth exponent;
* :mod:`.scene`: uncontrolled iterations, then the controller on, and the distance to
  the controlled 1/1 orbit.

The sweep of a model file is :mod:`..sweeps.model_file` (beside the 1-DOF sweep), its
figure set :mod:`..figures.near_grazing`.

May import: :mod:`grazing_control.recordings` and below (here: dynamics, oscillator).
"""
