"""The simulator's settings for an n-DOF scene: a model file and the 1-DOF table's other values.

sim_node with ``model_file`` set (a YAML model of docs/ndof_model.md) simulates the
n-DOF oscillator instead of the study's (issue 17). Everything that is not the model --
mode, time scale, state stream period, timeouts, max periods, actuation delay, loss,
seeds -- keeps its meaning and its validation (:func:`settings_from_values` of
:mod:`grazing_control.plant.settings`, run with the model's forcing frequency so that
every bound on a time reads the n-DOF period T = 2 pi / omega). The model comes whole
from the file, except ``delta_d``: the parameter, when given, replaces the file's
(``grazing run --delta-d``).

What the n-DOF scene does not do (yet) is refused with one line naming the parameter
and why (ParameterError), never half-applied: the 1-DOF model parameters (zeta, r,
omega, tau0, pi2_offset: the file gives them), an initial state other than the grazing
point (x0, v0), the velocity noise at Pi2 (``noise``), the injected measurement noise,
the force pulse, and fidelities other than exact. The sensor of the state stream
(``sensor_noise``, ``sensor_velocity``, ``sensor_quantum``, ``sensor_bias``,
``sensor_seed``) measures every coordinate (plant.ndof_engine.measure_coordinates).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

from grazing_control.oscillator.ndof.model import NdofModel, load_model
from grazing_control.oscillator.params import ParameterError
from grazing_control.plant.settings import (MODEL_KEYS, SimSettings, default_values,
                                            settings_from_values)

__all__ = ["NdofSettings", "ndof_settings_from_values", "load_model_file", "UNSUPPORTED"]

#: The table's values an n-DOF scene refuses unless left at their defaults, and why.
UNSUPPORTED = {
    "zeta": "the model file gives the n-DOF model (M, C, K, f, omega, r, phase, pi2_offset)",
    "r": "the model file gives the coefficient of restitution",
    "omega": "the model file gives the forcing frequency",
    "tau0": "the model file gives the forcing phase",
    "pi2_offset": "the model file gives pi2_offset",
    "x0": "an n-DOF scene starts at the grazing point X** (NaN)",
    "v0": "an n-DOF scene starts at the grazing point X** (NaN)",
    "noise": "the velocity noise at Pi2 is not built for n-DOF",
    "measurement_noise": "the injected measurement noise is not built for n-DOF",
    "pulse_width": "the force pulse is not built for n-DOF (the kick is a velocity jump)",
    "fidelity": "only the exact flow is built for n-DOF",
    "delta_d_drift": "the drifting wall is not built for n-DOF",
    "contact": "the compliant stop is not built for n-DOF (the rigid wall only)",
    "contact_stiffness": "the compliant stop is not built for n-DOF (the rigid wall only)",
    "contact_damping": "the compliant stop is not built for n-DOF (the rigid wall only)",
    "friction": "dry friction is not built for n-DOF",
    "friction_static": "dry friction is not built for n-DOF",
}


@dataclass(frozen=True)
class NdofSettings(SimSettings):
    """:class:`SimSettings` of an n-DOF scene: ``model`` (with the scene's delta_d) and
    the file it came from. ``params`` is the 1-DOF default model with the n-DOF forcing
    frequency (only its period is read)."""

    model: NdofModel | None = None
    model_file: str = ""

    def describe(self) -> str:
        """One line for the node's start-up log: the model, mode, scene, actuation."""
        m = self.model
        text = (f"model_file={self.model_file} n={m.n} i_w={m.i_w} i_a={m.i_a} "
                f"mode={self.mode} delta_d={m.delta_d!r} max_periods={self.max_periods} "
                f"state_period={self.state_period} "
                f"actuation={'scheduled' if self.scheduled else 'on_arrival'} "
                f"actuation_delay={self.actuation_delay!r}")
        if not self.sensor.exact or not self.sensor.velocity:
            sn = self.sensor
            text += (f" sensor noise={sn.noise!r} velocity={str(sn.velocity).lower()} "
                     f"quantum={sn.quantum!r} bias={sn.bias!r} seed={sn.seed}")
        if self.faults.active:
            text += f" faults loss={self.loss!r} jitter={self.jitter!r} seed={self.seed}"
        return text


def load_model_file(path: str) -> NdofModel:
    """The model of a YAML file (docs/ndof_model.md); ParameterError naming ``model_file``
    and the reason for a file that is missing, unreadable or invalid."""
    from grazing_control.support.files import YamlFileError

    try:
        return load_model(path)
    except ParameterError as exc:
        raise ParameterError(f"model_file={path!r} is invalid: {exc}") from None
    except YamlFileError as exc:       # "PATH: why" (support/files.read_yaml_file)
        why = str(exc).removeprefix(f"{path}: ")
        raise ParameterError(f"model_file={path!r} is invalid: cannot read it as a model "
                             f"YAML file ({why})") from None
    except (OSError, TypeError) as exc:
        reason = exc.strerror if isinstance(exc, OSError) and exc.strerror else str(exc)
        raise ParameterError(f"model_file={path!r} is invalid: cannot read it as a model "
                             f"YAML file ({reason.splitlines()[0] if reason else type(exc).__name__})"
                             ) from None


def ndof_settings_from_values(values: dict, model_file: str,
                              model: NdofModel | None = None) -> NdofSettings:
    """Validate an n-DOF scene's values (module docstring); ParameterError on a bad one.

    ``values`` maps names of the 1-DOF table to values (left out: the default; ``delta_d``
    left out: the file's); ``model`` is the file's model when already loaded.
    """
    model = load_model_file(model_file) if model is None else model
    defaults = default_values()
    for name, why in UNSUPPORTED.items():
        if name in values and not _same(values[name], defaults[name]):
            raise ParameterError(f"{name}={values[name]!r} is invalid with model_file="
                                 f"{model_file!r}: valid is its default "
                                 f"{defaults[name]!r} ({why})")
    if "delta_d" in values:
        delta_d = float(values["delta_d"])
        if not math.isfinite(delta_d):
            raise ParameterError(f"delta_d={delta_d!r} is invalid: valid range is a finite "
                                 "real number (d - d* of the model file's wall coordinate)")
        model = dataclasses.replace(model, delta_d=delta_d)
    rest = {k: v for k, v in values.items() if k not in MODEL_KEYS and k not in UNSUPPORTED}
    # the 1-DOF validation with the n-DOF forcing frequency: its bounds on times read T
    base = settings_from_values({**rest, "omega": model.omega})
    fields = {f.name: getattr(base, f.name) for f in dataclasses.fields(SimSettings)}
    return NdofSettings(**fields, model=model, model_file=str(model_file))


def _same(value, default) -> bool:
    """Whether a parameter value is its default (NaN equals NaN)."""
    if isinstance(default, float) and isinstance(value, (int, float)) and not isinstance(
            value, bool):
        return float(value) == default or (math.isnan(default) and math.isnan(float(value)))
    return value == default
