"""The ``grazing`` command line (layer 7 of 7, the top; docs/architecture.md).

:mod:`.commands` builds the parser and runs the subcommands, :mod:`.console` is the
console script's entry point (quiet on an early Ctrl-C), :mod:`.bag` the ``grazing bag``
group. ``python -m grazing_control.cli`` runs it too.

May import every layer below.
"""

__all__ = ["main", "build_parser"]


def __getattr__(name):
    """``main`` and ``build_parser`` of :mod:`.commands`, loaded on first use: the console
    script imports this package before it loads numpy and scipy (quiet Ctrl-C)."""
    if name in __all__:
        from . import commands

        return getattr(commands, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
