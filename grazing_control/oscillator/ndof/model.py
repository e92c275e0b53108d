"""The linear n-DOF impact oscillator and its YAML loader (schema: docs/ndof_model.md).

Model (issue 17, generalising study Eq. 1)::

    M x'' + C x' + K x = f cos(omega t + phase)     while x[i_w] < d
    v[i_w]+ = -r v[i_w]-                            at x[i_w] = d, v[i_w]- > 0

with the other velocities unchanged at an impact. As in the 1-DOF core
(oscillator/params.py) the wall is given relative to grazing: ``delta_d = d - d*``,
where d* (the grazing clearance, the maximum of x[i_w] on the non-impacting periodic
response) is derived, never stored. The controller's kick acts on the velocity of
coordinate ``i_a``.

Validation happens once, in the constructor; a bad value raises
:class:`~grazing_control.oscillator.params.ParameterError` naming the field and its
valid range.
"""

from __future__ import annotations

import copy
import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from grazing_control.oscillator.params import ParameterError

__all__ = ["NdofModel", "load_model", "model_from_mapping"]


def _matrix(name: str, value, n: int | None) -> np.ndarray:
    try:
        a = np.array(value, dtype=float)
    except (TypeError, ValueError):
        raise ParameterError(f"{name}={value!r} is invalid: expected a real n x n matrix") from None
    if a.ndim != 2 or a.shape[0] != a.shape[1] or a.shape[0] == 0 or (n is not None and a.shape[0] != n):
        want = "n x n" if n is None else f"{n} x {n}"
        raise ParameterError(f"{name} has shape {a.shape}: valid shape is {want}")
    if not np.all(np.isfinite(a)):
        raise ParameterError(f"{name} is invalid: entries must be finite real numbers")
    a.setflags(write=False)
    return a


def _symmetric(name: str, a: np.ndarray, definite: bool) -> None:
    if not np.allclose(a, a.T, rtol=1e-12, atol=1e-14 * max(1.0, float(np.abs(a).max()))):
        raise ParameterError(f"{name} is invalid: it must be symmetric")
    lam = np.linalg.eigvalsh(a)
    if definite and not lam[0] > 0.0:
        raise ParameterError(f"{name} is invalid: it must be positive definite (smallest eigenvalue {lam[0]!r})")
    if not definite and lam[0] < -1e-12 * max(1.0, float(abs(lam[-1]))):
        raise ParameterError(f"{name} is invalid: it must be positive semi-definite (smallest eigenvalue {lam[0]!r})")


def _real(name: str, value, ok, valid: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.floating, np.integer)):
        raise ParameterError(f"{name}={value!r} is invalid: expected a real number")
    v = float(value)
    if not (math.isfinite(v) and ok(v)):
        raise ParameterError(f"{name}={value!r} is invalid: valid range is {valid}")
    return v


def _index(name: str, value, n: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or not 0 <= int(value) < n:
        raise ParameterError(f"{name}={value!r} is invalid: valid range is an integer 0 <= {name} < {n}")
    return int(value)


@dataclass(frozen=True, eq=False)
class NdofModel:
    """Parameters of the linear n-DOF impact oscillator (docs/ndof_model.md).

    Parameters
    ----------
    M, C, K : (n, n) array_like
        Mass (symmetric positive definite), damping and stiffness (symmetric positive
        semi-definite); a forcing at an undamped resonance is refused by the flow.
    f : (n,) array_like
        Forcing amplitude vector: the forcing is ``f cos(omega t + phase)``.
    omega : float
        Forcing frequency, finite and > 0.
    i_w : int
        Index of the coordinate that meets the wall, 0 <= i_w < n.
    delta_d : float
        Wall position relative to grazing, d - d* (any finite value; < 0 impacts).
    r : float
        Coefficient of restitution, 0 < r <= 1.
    i_a : int
        Index of the actuated coordinate (controller kick on its velocity), 0 <= i_a < n.
    phase : float
        Forcing phase at t = 0 (the 1-DOF tau0), finite; reduced modulo 2 pi.
    pi2_offset : float
        Phase of section Pi2 after Pi1, in (0, 2 pi), as in the 1-DOF core.
    """

    M: np.ndarray
    C: np.ndarray
    K: np.ndarray
    f: np.ndarray
    omega: float
    i_w: int
    delta_d: float = 0.0
    r: float = 0.68
    i_a: int = 0
    phase: float = 0.0
    pi2_offset: float = math.pi / 2

    def __post_init__(self) -> None:
        M = _matrix("M", self.M, None)
        n = M.shape[0]
        C = _matrix("C", self.C, n)
        K = _matrix("K", self.K, n)
        _symmetric("M", M, True)
        _symmetric("C", C, False)
        _symmetric("K", K, False)
        try:
            f = np.array(self.f, dtype=float).reshape(-1) if np.ndim(self.f) <= 1 else None
        except (TypeError, ValueError):
            f = None
        if f is None or f.shape != (n,) or not np.all(np.isfinite(f)):
            raise ParameterError(f"f={self.f!r} is invalid: expected {n} finite real numbers")
        f.setflags(write=False)
        omega = _real("omega", self.omega, lambda v: v > 0.0, "finite omega > 0")
        delta_d = _real("delta_d", self.delta_d, lambda v: True, "any finite real number")
        r = _real("r", self.r, lambda v: 0.0 < v <= 1.0, "0 < r <= 1")
        phase = _real("phase", self.phase, lambda v: True, "any finite real number") % (2 * math.pi)
        pi2 = _real("pi2_offset", self.pi2_offset, lambda v: 0.0 < v < 2 * math.pi, "0 < pi2_offset < 2*pi")
        i_w = _index("i_w", self.i_w, n)
        i_a = _index("i_a", self.i_a, n)
        for name, value in dict(M=M, C=C, K=K, f=f, omega=omega, i_w=i_w, delta_d=delta_d,
                                r=r, i_a=i_a, phase=phase, pi2_offset=pi2).items():
            object.__setattr__(self, name, value)

    def with_clearance(self, delta_d) -> "NdofModel":
        """This model with its wall at Delta d = ``delta_d`` (validated as the constructor
        does: ParameterError naming delta_d), everything else shared, not validated
        again: a filter that moves the wall at every section (dynamics/estimation/
        augmented.py) spent half its time checking the same M, C, K. The copy's
        :attr:`dynamics` is this model's."""
        value = _real("delta_d", delta_d, lambda v: True, "any finite real number")
        new = copy.copy(self)
        object.__setattr__(new, "delta_d", value)
        object.__setattr__(new, "_dynamics", self.dynamics)
        return new

    @property
    def dynamics(self) -> "NdofModel":
        """The model this one was made from by :meth:`with_clearance` (itself if none):
        the same M, C, K, f, omega, indices, r, phase and Pi2, so the same free flow
        (:class:`grazing_control.oscillator.ndof.flow.NdofFlow` does not depend on the
        clearance)."""
        return self.__dict__.get("_dynamics", self)

    @property
    def n(self) -> int:
        """Number of degrees of freedom."""
        return self.M.shape[0]

    @property
    def period(self) -> float:
        """Forcing period T = 2 pi / omega."""
        return 2.0 * math.pi / self.omega


_FIELDS = ("M", "C", "K", "f", "omega", "i_w", "delta_d", "r", "i_a", "phase", "pi2_offset")


def model_from_mapping(data) -> NdofModel:
    """Build a model from a mapping (the parsed YAML of docs/ndof_model.md)."""
    if not isinstance(data, dict):
        raise ParameterError(f"model file content is invalid: expected a mapping, got {type(data).__name__}")
    unknown = sorted(set(data) - set(_FIELDS))
    if unknown:
        raise ParameterError(f"unknown model field(s) {unknown}: valid fields are {list(_FIELDS)}")
    missing = [k for k in ("M", "C", "K", "f", "omega", "i_w") if k not in data]
    if missing:
        raise ParameterError(f"model field(s) {missing} missing: required are M, C, K, f, omega, i_w")
    return NdofModel(**{k: data[k] for k in _FIELDS if k in data})


def load_model(path) -> NdofModel:
    """Load and validate a model YAML file (schema: docs/ndof_model.md), read within the
    limits of :func:`grazing_control.support.files.read_yaml_file` (YamlFileError, a
    ValueError naming the file, beyond them)."""
    from grazing_control.support.files import read_yaml_file

    return model_from_mapping(read_yaml_file(Path(path)))


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
