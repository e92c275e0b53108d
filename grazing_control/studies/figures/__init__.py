"""The study's Figs. 1 and 2 (spec section 8, issue 10 §3): panels and their numbers.

One module per panel family, each a pure computation of the panel's data from the
core followed by a matplotlib (Agg) drawing of exactly that data:

* :mod:`.bifurcation`: 1(a), 1(b), brute-force diagrams on Pi2 across grazing
  (:func:`grazing_control.studies.sweeps.sweep`) with the 1/1 branch;
* :mod:`.branches`: 1(c), 2(c), the 1/1 branch by continuation, uncontrolled and
  controlled, stability marked;
* :mod:`.multipliers`: 1(d), 2(d), 2(e), Floquet multipliers, shooting (lines)
  against perturbation (circles);
* :mod:`.constraints`: 2(a), 2(b), the control constraints against c2 and the
  admissible set;
* :mod:`.scenes`: 2(f), 2(g), the two control scenes;
* :mod:`.report`: figures.md, the numbers read off each panel next to the study's;
* :mod:`.build`: everything in one call (:func:`make_figures`), full or quick;
* :mod:`.ndof`: the n-DOF figure set of issue 17 (``grazing figures --model FILE``).

``grazing figures [--out DIR] [--quick]`` (:mod:`.command`) is the command line.
"""

__all__ = ["make_figures", "Settings", "FULL", "QUICK"]


def __getattr__(name):
    """The build's names, imported on first use (PEP 562): the command line registers
    `grazing figures` through :mod:`.command` without importing the core, scipy and
    matplotlib, so `grazing --version` and every other command start faster."""
    if name in __all__:
        from . import build

        return getattr(build, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
