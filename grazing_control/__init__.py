"""grazing_control: exact simulation and discrete control of grazing in impact oscillators.

The numerical core (every module of this package except :mod:`grazing_control.ros`)
never imports rclpy. The path of the data: parameters (:mod:`.params`) -> exact flow
(:mod:`.flow`) and impacts (:mod:`.impact`) -> Poincare maps (:mod:`.maps`), simulation
(:mod:`.simulate`) and periodic orbits (:mod:`.orbits`) -> continuation
(:mod:`.continuation`) -> control design (:mod:`.design`) -> nodes -> recordings
(:mod:`.recording`) -> analysis.
"""

from grazing_control.oscillator.params import OscillatorParams, ParameterError

__all__ = ["OscillatorParams", "ParameterError"]
__version__ = "0.1.0"
