"""n-DOF studies (issue 17): the 1/1 orbit near grazing, its multipliers against Delta d,
brute-force diagrams and control scenes, over any model file (docs/ndof_commands.md).

* :mod:`.branch`: the 1/1 orbit of an :class:`~grazing_control.dynamics.maps.ndof_map.NdofMap`
  by shooting from the leading-order discontinuity-map prediction, its multipliers on a
  log grid of Delta d and the fitted growth exponent;
* :mod:`.diagram`: the brute-force bifurcation diagram on Pi2 (local processes, or a
  Dask cluster when one is given);
* :mod:`.scene`: uncontrolled iterations, then the controller on, and the distance to
  the controlled 1/1 orbit.

These are written over the period-map protocol (dynamics/maps/model.py) with the n-DOF
model's map; the 1-DOF closed-form studies stay in :mod:`..sweeps` and :mod:`..figures`.

May import: :mod:`grazing_control.recordings` and below (here: dynamics, oscillator).
"""
