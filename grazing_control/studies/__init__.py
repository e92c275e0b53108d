"""The study's applications: figures, sweeps, robustness charts, the demo (main job).

Layer 6 of 7 (docs/architecture.md). :mod:`.figures` (the study's Figs. 1 and 2),
:mod:`.sweeps` (parameter sweeps on all cores or Dask), :mod:`.ndof` (the n-DOF orbit
near grazing, diagram and control scene of issue 17), :mod:`.robustness` (the actual
delay, lost corrections, noise, jitter) and :mod:`.demo` (the two control scenes through
the real nodes, recorded and reported).

May import: :mod:`grazing_control.recordings` and below.
"""
