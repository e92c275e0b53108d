"""The 1/1 orbit near grazing of a model file's model (any n; issue 17), a study that the
1-DOF model answers in closed form (dynamics/orbits) and a model file by shooting from the
local map's prediction (docs/ndof_commands.md):

* :mod:`.branch`: the 1/1 orbit of an :class:`~grazing_control.dynamics.maps.modal_map.ModalMap`
  by shooting from the leading-order discontinuity-map prediction, its multipliers on a
  log grid of Delta d and the fitted growth exponent;
* :mod:`.scene`: uncontrolled iterations, then the controller on, and the distance to
  the controlled 1/1 orbit.

The sweep of a model file is :mod:`..sweeps.model_file` (beside the 1-DOF sweep), its
figure set :mod:`..figures.near_grazing`.

May import: :mod:`grazing_control.recordings` and below (here: dynamics, oscillator).
"""
