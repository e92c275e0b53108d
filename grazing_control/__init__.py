"""grazing_control: exact simulation and discrete control of grazing in impact oscillators.

One folder per layer, arrows pointing down (docs/architecture.md): oscillator (parameters,
exact flow, impacts, the kernel) -> dynamics (maps, orbits, shooting, continuation,
design, simulation) -> plant (the simulator's engine without ROS) -> ros (nodes,
launcher, recording) -> recordings (analysis, replay) -> studies (figures, sweeps,
robustness, demo) -> cli. Below ros nothing imports rclpy.

``OscillatorParams`` and ``ParameterError`` are importable from here; they load on first
use, so that the ``grazing`` console script reaches its quiet Ctrl-C handler before any
other import (:mod:`grazing_control.cli.console`).
"""

__all__ = ["OscillatorParams", "ParameterError"]
__version__ = "0.1.0"


def __getattr__(name):
    if name in __all__:
        from .oscillator import params

        return getattr(params, name)
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
