"""Helpers every layer may use: argument types, parameter files and the shared look of
the plots.

Not a layer of the model: :mod:`.arguments` (argparse types with one-line errors naming
the range), :mod:`.files` (the one reader of parameter files, within fixed limits, and
the atomic writer) and :mod:`.plotting` (the Agg backend, one look, PNG + SVG output). Imports
nothing else of grazing_control (docs/architecture.md).
"""
