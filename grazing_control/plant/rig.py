"""A rig in SI units, and the study's dimensionless model it is (docs/rig.md).

A rig file (YAML, every dimensional value written with its unit) describes a mass on a
spring and damper driven towards a rigid stop:

    m x'' + c x' + k x = F0 cos(Omega t + phi),   x < g;    x'+ = -r x'-  at x = g,

with the forcing a force of amplitude F0, or a base excitation y = Y cos(Omega t + phi)
of a frame carrying the stop (then x is the mass's displacement relative to the frame and
F0 = m Omega^2 Y). Time tau = omega_n t and length x~ = x / l with omega_n = sqrt(k/m) and
l = F0 / k (the static deflection) give the study's Eq. 1 exactly,

    x~'' + 2 zeta x~' + x~ = cos(omega tau + phi),   zeta = c / (2 sqrt(k m)),
    omega = Omega / omega_n,   d = g / l,   Delta d = d - d*(zeta, omega),

derived in docs/rig.md. Velocities scale by omega_n l, forces by k l, times by
1/omega_n. A correction Delta v~ on Pi2 is Delta v = omega_n l Delta v~ (m/s), an impulse
m Delta v; as a pulse of width w its force is m Delta v / w. The study's law
Delta v~ = c1 Delta x~ + c2 Delta v~ reads Delta v = (c1 omega_n) Delta x + c2 Delta v.

:func:`load_rig` reads and validates a file (each refusal one :class:`RigError` line
naming the field); :class:`Rig` is the immutable rig, with :attr:`Rig.scales`,
:meth:`Rig.params` (the :class:`OscillatorParams`), :meth:`Rig.dimensionless` (the
sensor, actuator and timing in the model's units), and :func:`rig_with_model`, the
inverse used by ``grazing identify`` (a fitted model written back as a rig file).

The stop (the optional ``stop`` section, :class:`Stop`; issue 31) is the rigid wall of
the equation above by default, or a compliant stop pushing on the mass with a force F_c
while x > g, with Coulomb friction F_f on the guides (with either stop):

    kelvin_voigt:  F_c = K (x - g) + C x',
    hertz:         F_c = K_H (x - g)^{3/2} (1 + (3/2) A x')      (Hunt-Crossley),

K in N/m, C in N s/m, K_H in N/m^{3/2}, A in s/m, F_f in N. Divided by k l (the force
scale) with x = l x~, x' = omega_n l x~' they are the dimensionless laws of
docs/theory_contact.md (C1, C6) with

    k_c = K / k,   c_c = C omega_n / k = C / (m omega_n) = C / sqrt(k m),
    k_c = K_H sqrt(l) / k  (Hertz: K_H l^{3/2} / (k l)),   alpha = A omega_n l,
    F_f~ = F_f / (k l),

(:meth:`Rig.contact_values`, derived in docs/rig.md, "The stop"). ``restitution`` stays
the rigid model's r, the one the design is made for; the stop is the plant's.

A rig of n >= 2 masses (the ``masses`` form of the file, plant/rig_structure.py; issue
32) is the same object with a :class:`~grazing_control.plant.rig_structure.Structure`:
``mass``, ``omega_n`` and ``zeta`` are then those of the reference oscillator (the
impacting mass on its own springs, M_ww, sqrt(K_ww / M_ww), C_ww / (2 sqrt(K_ww M_ww))),
so that :attr:`Rig.scales` and :meth:`Rig.dimensionless` are one rule for every n, and
:meth:`Rig.model` is the dimensionless n-DOF model (for n = 1 the study's Eq. 1 as
M = K = f = 1, C = 2 zeta). The correction's impulse is m_a Delta v with the effective
mass m_a = 1 / (M^-1)_aa of the actuated mass (:attr:`Rig.effective_mass`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, replace

import numpy as np

from grazing_control.oscillator.ndof.model import NdofModel
from grazing_control.oscillator.params import OscillatorParams, ParameterError
from grazing_control.plant.contact_plant import CONTACTS
from grazing_control.plant.rig_fields import (MAGNITUDE, RigError, _number, _one_of, _q,
                                              _section)
from grazing_control.plant.rig_structure import (N_MASSES, Structure, read_indices,
                                                 read_masses, rig_with_ndof_model,
                                                 write_structure)
from grazing_control.support.units import format_quantity

__all__ = ["RigError", "Scales", "Sensor", "Actuator", "Stop", "Rig", "load_rig", "rig_from_dict",
           "rig_to_dict", "rig_with_model", "MIN_SAMPLES_PER_PERIOD", "MAX_SAMPLES_PER_PERIOD",
           "MAGNITUDE"]

TWO_PI = 2.0 * math.pi

#: Fewest sensor samples per forcing period a Pi2 estimate from the stream is made from
#: (the model estimator fits the period's samples, docs/theory_estimation.md).
MIN_SAMPLES_PER_PERIOD = 20
#: Most sensor samples per forcing period: the estimator handles every sample of a
#: period at each section (its work grows with their number); decimate a faster stream.
MAX_SAMPLES_PER_PERIOD = 10000
@dataclass(frozen=True)
class Scales:
    """The rig's units of the dimensionless model: tau = omega_n t, x~ = x / length."""

    omega_n: float       # rad/s: 1 / time unit
    length: float        # m: l = F0 / k
    mass: float          # kg

    @property
    def time(self) -> float:
        """Seconds per unit of dimensionless time, 1 / omega_n."""
        return 1.0 / self.omega_n

    @property
    def velocity(self) -> float:
        """m/s per unit of dimensionless velocity, omega_n l."""
        return self.omega_n * self.length

    @property
    def force(self) -> float:
        """N per unit of dimensionless force, k l = m omega_n^2 l (= F0 for a force)."""
        return self.mass * self.omega_n ** 2 * self.length


@dataclass(frozen=True)
class Sensor:
    """The motion sensor: rate (Hz), position noise (m, std), resolution (m, 0: none),
    latency (s), velocity noise (m/s, std) when it also measures the velocity."""

    rate: float
    noise: float
    resolution: float
    latency: float
    velocity: bool
    velocity_noise: float = 0.0


@dataclass(frozen=True)
class Actuator:
    """The actuator: force pulse width (s), force limit (N, 0: none), latency (s) from a
    command's apply time to the force, force constant (N/A, 0: not given), bandwidth
    (Hz, 0: ideal) of a first-order lag between the command and the force (issue 29)."""

    pulse_width: float
    force_limit: float
    latency: float
    force_constant: float = 0.0
    bandwidth: float = 0.0


@dataclass(frozen=True)
class Stop:
    """The stop (module docstring): ``type`` one of plant.contact_plant.CONTACTS;
    ``stiffness`` K (N/m; Hertz K_H in N/m^1.5), ``damping`` C (N s/m; Hertz A in s/m),
    ``friction`` F_f and ``friction_static`` F_s >= F_f (N; 0: none).
    The rigid wall has none of them (0)."""

    type: str = "rigid"
    stiffness: float = 0.0
    damping: float = 0.0
    friction: float = 0.0
    friction_static: float = 0.0


@dataclass(frozen=True)
class Rig:
    """A rig in SI units (module docstring). ``forcing`` 'force' (amplitude in N) or
    'base' (amplitude in m, the stop on the frame); ``phase`` the forcing phase at the
    rig clock's t = 0 (rad); ``budget`` (s): from a Pi2 section to the centre of its
    force pulse, the actuation delay the design is made for."""

    mass: float
    omega_n: float
    zeta: float
    restitution: float
    gap: float
    forcing: str
    amplitude: float
    frequency: float
    phase: float
    sensor: Sensor
    actuator: Actuator
    budget: float
    pi2_offset: float = math.pi / 2
    stop: Stop = Stop()
    structure: Structure | None = None

    @property
    def n(self) -> int:
        """The number of masses."""
        return 1 if self.structure is None else self.structure.n

    @property
    def effective_mass(self) -> float:
        """m_a = 1 / (M^-1)_aa of the actuated mass (kg; ``mass`` for n = 1): the
        impulse of a correction Delta v_a is m_a Delta v_a (plant/rig_structure.py)."""
        return self.mass if self.structure is None else self.structure.effective_mass

    @property
    def measured(self) -> tuple:
        """The indices of the masses the sensor measures ((0,) for n = 1)."""
        return (0,) if self.structure is None else self.structure.measured

    @property
    def stiffness(self) -> float:
        """k = m omega_n^2 (N/m)."""
        return self.mass * self.omega_n ** 2

    @property
    def damping(self) -> float:
        """c = 2 zeta sqrt(k m) (N s/m)."""
        return 2.0 * self.zeta * math.sqrt(self.stiffness * self.mass)

    @property
    def natural_frequency(self) -> float:
        """f_n = omega_n / 2 pi (Hz)."""
        return self.omega_n / TWO_PI

    @property
    def force_amplitude(self) -> float:
        """F0 (N): the force, or m Omega^2 Y for a base excitation."""
        if self.forcing == "force":
            return self.amplitude
        return self.mass * (TWO_PI * self.frequency) ** 2 * self.amplitude

    @property
    def scales(self) -> Scales:
        return Scales(self.omega_n, self.force_amplitude / self.stiffness, self.mass)

    @property
    def forcing_period(self) -> float:
        """1 / f (s)."""
        return 1.0 / self.frequency

    def params(self) -> OscillatorParams:
        """The study's model of this rig: zeta, r, omega = f / f_n, Delta d = g / l - d*,
        tau0 = 0 (the simulator's time origin is a Pi2 sample: :meth:`rig_time`).
        A rig of n >= 2 masses has no 1-DOF model: RigError (use :meth:`model`)."""
        if self.structure is not None:
            raise RigError(f"masses: this rig has {self.n} masses: its model is the n-DOF "
                           "model (grazing rig FILE, grazing design --rig FILE), not the "
                           "1-DOF study's")
        s = self.scales
        base = OscillatorParams(zeta=self.zeta, r=self.restitution,
                                omega=TWO_PI * self.frequency / self.omega_n,
                                pi2_offset=self.pi2_offset)
        return base.with_(delta_d=self.gap / s.length - base.d_star)

    def model(self) -> NdofModel:
        """The dimensionless n-DOF model of this rig (docs/ndof_model.md; the scaling in
        plant/rig_structure.py): M / m_ref, C / sqrt(k_ref m_ref), K / k_ref, f / F0,
        omega = Omega / omega_n, i_w the impacting mass, i_a the actuated one,
        Delta d = g / l - d*, phase 0 (as :meth:`params`' tau0: the model's t = 0 is a Pi2
        section, :meth:`rig_time`). For n = 1: M = K = f = 1, C = 2 zeta and the
        omega, Delta d of :meth:`params`."""
        if self.structure is None:
            p = self.params()
            return NdofModel(M=[[1.0]], C=[[2.0 * p.zeta]], K=[[1.0]], f=[1.0], omega=p.omega,
                             i_w=0, delta_d=p.delta_d, r=p.r, i_a=0, phase=0.0,
                             pi2_offset=p.pi2_offset)
        from grazing_control.oscillator.ndof.flow import grazing_clearance

        st, s = self.structure, self.scales
        k_ref = self.stiffness
        if self.forcing == "force":
            f = np.zeros(st.n)
            f[st.forced] = 1.0
        else:            # f = Omega^2 Y M 1, F0 = m_ref Omega^2 Y
            f = np.array(st.masses, dtype=float) / self.mass
        model = NdofModel(M=st.M / self.mass, C=st.C / math.sqrt(k_ref * self.mass),
                          K=st.K / k_ref, f=f, omega=TWO_PI * self.frequency / self.omega_n,
                          i_w=st.impacting, r=self.restitution, i_a=st.actuated, phase=0.0,
                          pi2_offset=self.pi2_offset)
        return replace(model, delta_d=self.gap / s.length - grazing_clearance(model))

    def section_phase(self) -> float:
        """tau2: the forcing phase of the Pi2 section (rad, in [0, 2 pi)), the grazing
        phase + pi2_offset: the 1-DOF study's for one mass, the n-DOF model's for n."""
        if self.structure is not None:
            from grazing_control.oscillator.ndof.flow import grazing_phase

            m = self.model()
            return (grazing_phase(m) + m.pi2_offset) % TWO_PI
        return self.params().tau2

    def section_time(self) -> float:
        """The rig-clock time (s) of the first Pi2 section at or after t = 0: where the
        forcing phase Omega t + phi equals tau2 (mod 2 pi). The model's t = 0 is there."""
        return ((self.section_phase() - self.phase) % TWO_PI) / (TWO_PI * self.frequency)

    def rig_time(self, tau: float) -> float:
        """Rig-clock seconds of dimensionless model time tau."""
        return self.section_time() + tau / self.omega_n

    def model_time(self, t: float) -> float:
        """Dimensionless model time of rig-clock seconds t (inverse of :meth:`rig_time`)."""
        return (t - self.section_time()) * self.omega_n

    def dimensionless(self) -> dict:
        """The sensor, actuator and timing in the model's units: state_period (between
        two sensor samples), sensor_noise, sensor_quantum, sensor_velocity,
        sensor_velocity_noise, sensor_latency, pulse_width, force_limit (0: none),
        actuator_latency, actuator_bandwidth (1 / tau_a in model time: 2 pi f / omega_n,
        0: ideal), actuation_delay (the budget), time_scale (model time per second
        of wall time at physical speed: omega_n)."""
        s, sen, act = self.scales, self.sensor, self.actuator
        return {
            "state_period": self.omega_n / sen.rate,
            "sensor_noise": sen.noise / s.length,
            "sensor_quantum": sen.resolution / s.length,
            "sensor_velocity": sen.velocity,
            "sensor_velocity_noise": sen.velocity_noise / s.velocity,
            "sensor_latency": sen.latency * self.omega_n,
            "pulse_width": act.pulse_width * self.omega_n,
            "force_limit": act.force_limit / s.force,
            "actuator_latency": act.latency * self.omega_n,
            "actuator_bandwidth": TWO_PI * act.bandwidth / self.omega_n,
            "actuation_delay": self.budget * self.omega_n,
            "time_scale": self.omega_n,
        }

    def contact_values(self) -> dict:
        """The stop as sim_node's dimensionless parameters (docs/nodes.md; module
        docstring for the scaling): contact, contact_stiffness k_c, contact_damping
        (c_c, or Hunt-Crossley alpha for hertz), friction and friction_static (F / k l).
        The rigid wall gives contact 'rigid' only."""
        st = self.stop
        if st.type == "rigid":
            return {"contact": "rigid"}
        k, s = self.stiffness, self.scales
        friction = {"friction": st.friction / s.force,
                    "friction_static": st.friction_static / s.force}
        if st.type == "hertz":
            return {"contact": "hertz", "contact_stiffness": st.stiffness * math.sqrt(s.length) / k,
                    "contact_damping": st.damping * s.velocity, **friction}
        return {"contact": "kelvin_voigt", "contact_stiffness": st.stiffness / k,
                "contact_damping": st.damping / (self.mass * self.omega_n), **friction}

    # ------------------------------------------------------------------ SI of results
    def gains_si(self, c1: float, c2: float) -> dict:
        """The law Delta v~ = c1 Delta x~ + c2 Delta v~ in SI: Delta v = c1_si Delta x +
        c2 Delta v (c1_si = c1 omega_n, 1/s), and as the pulse's force
        F = kx Delta x + kv Delta v (kx = m c1 omega_n / w in N/m, kv = m c2 / w in N s/m)."""
        w = self.actuator.pulse_width
        out = {"c1_per_s": c1 * self.omega_n, "c2": c2}
        if w > 0.0:
            out["force_gain_position_N_per_m"] = self.mass * c1 * self.omega_n / w
            out["force_gain_velocity_N_s_per_m"] = self.mass * c2 / w
        return out

    def state_gains_si(self, k) -> dict:
        """The n-DOF law Delta v~_a = k^T z~ over z~ = (x~_0 .. x~_{n-1}, v~_0 .. v~_{n-1})
        in SI: Delta v_a = sum_i (k_i omega_n) x_i + sum_i k_{n+i} v_i (x~ = x / l,
        v~ = v / (omega_n l), Delta v_a = omega_n l Delta v~_a), and as the pulse's force
        F = m_a Delta v_a / w (N/m and N s/m; m_a :attr:`effective_mass`)."""
        k = [float(v) for v in k]
        n, w = len(k) // 2, self.actuator.pulse_width
        out = {"position_gains_per_s": [v * self.omega_n for v in k[:n]],
               "velocity_gains": k[n:]}
        if w > 0.0:
            m = self.effective_mass
            out["force_gains_position_N_per_m"] = [m * v * self.omega_n / w for v in k[:n]]
            out["force_gains_velocity_N_s_per_m"] = [m * v / w for v in k[n:]]
        return out

    def correction_si(self, dv: float) -> dict:
        """A dimensionless correction Delta v~ as a velocity change (m/s) of the actuated
        mass, an impulse (N s, m_a Delta v) and, with a pulse width w, the pulse's force
        (N) over w."""
        v = dv * self.scales.velocity
        m = self.effective_mass
        out = {"velocity_m_per_s": v, "impulse_N_s": m * v}
        if self.actuator.pulse_width > 0.0:
            out["force_N"] = m * v / self.actuator.pulse_width
            out["pulse_width_s"] = self.actuator.pulse_width
        return out


# ---------------------------------------------------------------------- reading
_TOP = {"mass", "natural_frequency", "stiffness", "damping_ratio", "damping", "restitution",
        "gap", "forcing", "sensor", "actuator", "controller", "stop", "masses", "springs",
        "damping_ratios", "impacting"}
_FORCING = {"type", "amplitude", "frequency", "phase", "stop", "mass"}
_SENSOR = {"rate", "noise", "resolution", "latency", "measures", "velocity_noise", "masses"}
_ACTUATOR = {"pulse_width", "force_limit", "latency", "force_constant", "bandwidth", "mass"}
_CONTROLLER = {"budget", "pi2_offset"}
_STOP = {"type", "stiffness", "damping", "friction", "friction_static"}


def load_rig(path) -> Rig:
    """Read and validate a rig file (support.files.read_yaml_file: bounded, safe YAML)."""
    from grazing_control.support.files import read_yaml_file

    doc = read_yaml_file(path)
    try:
        return rig_from_dict(doc)
    except RigError as exc:
        raise RigError(f"{path}: {exc}") from None


def rig_from_dict(doc) -> Rig:
    """A :class:`Rig` from a rig file's mapping (module docstring; docs/rig.md)."""
    if not isinstance(doc, dict):
        raise RigError(f"the rig file holds {type(doc).__name__}, not a mapping of rig fields")
    unknown = sorted(set(map(str, doc)) - _TOP)
    if unknown:
        raise RigError(f"{unknown[0]} is not a rig field: valid fields are "
                       f"{', '.join(sorted(_TOP))}")
    positive = (lambda v: v > 0.0)
    if doc.get("masses") is not None:
        mass, omega_n, zeta, chain = read_masses(doc)
    else:
        given = [k for k in N_MASSES if doc.get(k) is not None]
        if given:
            raise RigError(f"{given[0]} is a field of the n-mass form: give masses (a list "
                           "of masses with their unit) with it, or remove it")
        mass, omega_n, zeta = _one_mass(doc)
        chain = None
    r = _number(doc, "restitution", lambda v: 0.0 < v < 1.0, "0 < restitution < 1")
    gap = _q(doc, "", "gap", "length", ok=positive,
             valid="gap > 0 (the stop on the +x side of the rest position: the mass "
                   "moves towards it by a positive distance)")
    return _rest(doc, mass, omega_n, zeta, r, gap, chain)


def _one_mass(doc) -> tuple:
    """(mass, omega_n, zeta) of the one-mass form: mass, natural_frequency or stiffness,
    damping_ratio or damping."""
    positive = (lambda v: v > 0.0)
    mass = _q(doc, "", "mass", "mass", ok=positive, valid="mass > 0")
    if _one_of(doc, "", "natural_frequency", "stiffness") == "natural_frequency":
        omega_n = TWO_PI * _q(doc, "", "natural_frequency", "frequency", ok=positive,
                              valid="natural_frequency > 0")
    else:
        omega_n = math.sqrt(_q(doc, "", "stiffness", "stiffness", ok=positive,
                               valid="stiffness > 0") / mass)
    if _one_of(doc, "", "damping_ratio", "damping") == "damping_ratio":
        zeta = _number(doc, "damping_ratio", lambda v: 0.0 < v < 1.0, "0 < damping_ratio < 1")
    else:
        c = _q(doc, "", "damping", "damping", ok=positive, valid="damping > 0")
        zeta = c / (2.0 * mass * omega_n)
        if not zeta < 1.0:
            raise RigError(f"damping={doc['damping']!r} is invalid: the damping ratio "
                           f"c / (2 sqrt(k m)) = {zeta:.6g} must be < 1 (an underdamped "
                           f"oscillator): valid range is damping < {2 * mass * omega_n:.6g} N*s/m")
    return mass, omega_n, zeta


def _rest(doc, mass, omega_n, zeta, r, gap, chain) -> Rig:
    """The forcing, sensor, actuator, controller and stop sections, for every n."""
    positive = (lambda v: v > 0.0)
    f = _section(doc, "forcing", _FORCING)
    kind = f.get("type", "force")
    if kind not in ("force", "base"):
        raise RigError(f"forcing.type={kind!r} is invalid: valid values are force, base")
    if kind == "force":
        if f.get("stop") is not None:
            raise RigError("forcing.stop is a base excitation's field (where the stop is "
                           "mounted): remove it for forcing.type force")
        amplitude = _q(f, "forcing.", "amplitude", "force", ok=positive,
                       valid="forcing.amplitude > 0 N")
    else:
        stop = f.get("stop")
        if stop != "frame":
            raise RigError(f"forcing.stop={stop!r} is invalid: a base excitation is modelled "
                           "with the stop riding on the frame (stop: frame); a stop fixed to "
                           "the ground is a moving wall in the frame's coordinate, not the "
                           "study's model (docs/rig.md)")
        amplitude = _q(f, "forcing.", "amplitude", "length", ok=positive,
                       valid="forcing.amplitude > 0 m (the frame's displacement amplitude)")
    frequency = _q(f, "forcing.", "frequency", "frequency", ok=positive,
                   valid="forcing.frequency > 0")
    phase = _q(f, "forcing.", "phase", "angle", default=0.0)

    s = _section(doc, "sensor", _SENSOR)
    measures = s.get("measures", "position")
    if measures not in ("position", "position_velocity"):
        raise RigError(f"sensor.measures={measures!r} is invalid: valid values are position, "
                       "position_velocity")
    rate = _q(s, "sensor.", "rate", "frequency", ok=positive, valid="sensor.rate > 0")
    nonneg = (lambda v: v >= 0.0)
    noise = _q(s, "sensor.", "noise", "length", ok=nonneg, valid="sensor.noise >= 0")
    resolution = _q(s, "sensor.", "resolution", "length", ok=nonneg,
                    valid="sensor.resolution >= 0 (0: none)", default=0.0)
    latency = _q(s, "sensor.", "latency", "time", ok=nonneg, valid="sensor.latency >= 0")
    vnoise = 0.0
    if measures == "position_velocity":
        vnoise = _velocity(s)
    elif s.get("velocity_noise") is not None:
        raise RigError("sensor.velocity_noise is given but sensor.measures is position: "
                       "set measures: position_velocity, or remove it")
    sensor = Sensor(rate, noise, resolution, latency, measures == "position_velocity", vnoise)

    a = _section(doc, "actuator", _ACTUATOR)
    width = _q(a, "actuator.", "pulse_width", "time", ok=nonneg,
               valid="actuator.pulse_width >= 0 (0: an impulse)")
    limit = _q(a, "actuator.", "force_limit", "force", ok=nonneg,
               valid="actuator.force_limit >= 0 (0: no limit)", default=0.0)
    alat = _q(a, "actuator.", "latency", "time", ok=nonneg, valid="actuator.latency >= 0",
              default=0.0)
    kf = _q(a, "actuator.", "force_constant", "force_constant", ok=positive,
            valid="actuator.force_constant > 0", default=0.0)
    bandwidth = _q(a, "actuator.", "bandwidth", "frequency", ok=nonneg,
                   valid="actuator.bandwidth >= 0 Hz (0: ideal)", default=0.0)
    actuator = Actuator(width, limit, alat, kf, bandwidth)

    c = _section(doc, "controller", _CONTROLLER)
    budget = _q(c, "controller.", "budget", "time", ok=positive, valid="controller.budget > 0")
    pi2_offset = _q(c, "controller.", "pi2_offset", "angle",
                    ok=lambda v: 0.0 < v < TWO_PI, valid="0 < pi2_offset < 2 pi",
                    default=math.pi / 2)

    structure = read_indices(doc, f, s, a, chain)
    stop = _stop(doc)
    if structure is not None and stop.type != "rigid":
        raise RigError(f"stop.type={stop.type!r} is invalid for a rig of {structure.n} "
                       "masses: valid value is rigid (the compliant stops are the one-mass "
                       "plant's)")
    rig = Rig(mass, omega_n, zeta, r, gap, kind, amplitude, frequency, phase, sensor,
              actuator, budget, pi2_offset, stop, structure)
    _check_model(rig, doc)
    _check_stop(rig, doc)
    return rig


def _stop(doc) -> Stop:
    """The ``stop`` section (default: the rigid wall); each field with its unit."""
    st = _section(doc, "stop", _STOP, required=False)
    kind = st.get("type", "rigid")
    if kind not in CONTACTS:
        raise RigError(f"stop.type={kind!r} is invalid: valid values are {', '.join(CONTACTS)}")
    if kind == "rigid":
        given = sorted(k for k in _STOP - {"type"} if st.get(k) is not None)
        if given:
            raise RigError(f"stop.{given[0]} is a compliant stop's field: remove it for "
                           "stop.type rigid (the wall's law is restitution)")
        return Stop()
    hertz = kind == "hertz"
    stiffness = _q(st, "stop.", "stiffness", "hertz_stiffness" if hertz else "stiffness",
                   ok=lambda v: v > 0.0, valid="stop.stiffness > 0")
    damping = _q(st, "stop.", "damping", "hertz_damping" if hertz else "damping",
                 ok=lambda v: v >= 0.0, valid="stop.damping >= 0", default=0.0)
    friction = _q(st, "stop.", "friction", "force", ok=lambda v: v >= 0.0,
                  valid="stop.friction >= 0 N (0: none)", default=0.0)
    static = _q(st, "stop.", "friction_static", "force", ok=lambda v: v >= friction,
                valid=f"stop.friction_static >= stop.friction = {friction!r} N",
                default=friction)
    return Stop(kind, stiffness, damping, friction, static)


def _check_stop(rig: Rig, doc) -> None:
    """A Kelvin-Voigt stop is an underdamped contact (docs/theory_contact.md C2):
    (2 zeta + c_c)^2 < 4 (1 + k_c) and c_c < 2 sqrt(k_c), in the rig's units."""
    if rig.stop.type != "kelvin_voigt":
        return
    v = rig.contact_values()
    kc, cc = v["contact_stiffness"], v["contact_damping"]
    # the largest C of both conditions, in N s/m (C = c_c m omega_n)
    limit = min(2.0 * math.sqrt(1.0 + kc) - 2.0 * rig.zeta, 2.0 * math.sqrt(kc))
    if not cc < limit:
        raise RigError(f"stop.damping={doc['stop']['damping']!r} is invalid: the contact must "
                       "be underdamped (docs/theory_contact.md C2): valid range is "
                       f"stop.damping < {limit * rig.mass * rig.omega_n:.6g} N*s/m")


def _velocity(s):
    value = s.get("velocity_noise")
    field = "sensor.velocity_noise"
    if value is None:
        raise RigError(f"{field} is missing: the std of the measured velocity, in m/s")
    if not isinstance(value, str):
        raise RigError(f"{field}={value!r} has no unit: write it in m/s or mm/s")
    text = value.strip()
    for unit, factor in (("mm/s", 1e-3), ("um/s", 1e-6), ("m/s", 1.0)):
        if text.endswith(unit):
            try:
                v = float(text[: -len(unit)])
            except ValueError:
                break
            if math.isfinite(v) and v >= 0.0:
                return v * factor
            break
    raise RigError(f"{field}={value!r} is invalid: a velocity >= 0 in m/s, mm/s or um/s")


def _check_model(rig: Rig, doc) -> None:
    """The derived model exists: omega away from resonance, the pulse inside the period."""
    try:
        p = rig.params() if rig.structure is None else rig.model()
    except ParameterError as exc:
        raise RigError(f"the model of this rig is invalid: {exc}") from None
    period = rig.forcing_period
    w = rig.actuator.pulse_width
    if not rig.budget + w / 2.0 < period:
        raise RigError(f"controller.budget={doc['controller']['budget']!r} is invalid: the "
                       f"pulse's end, budget + pulse_width / 2 = {rig.budget + w / 2:.6g} s, "
                       f"must lie within the forcing period {period:.6g} s")
    if not w <= 2.0 * rig.budget:
        raise RigError(f"actuator.pulse_width={doc['actuator']['pulse_width']!r} is invalid: a "
                       f"pulse centred at the budget must start after the section: valid "
                       f"range is pulse_width <= 2 budget = {2 * rig.budget:.6g} s")
    spp = rig.sensor.rate * period
    if not MIN_SAMPLES_PER_PERIOD <= spp <= MAX_SAMPLES_PER_PERIOD:
        raise RigError(f"sensor.rate={doc['sensor']['rate']!r} is invalid: {spp:.3g} samples "
                       f"per forcing period; valid range is {MIN_SAMPLES_PER_PERIOD} x "
                       f"forcing.frequency <= sensor.rate <= {MAX_SAMPLES_PER_PERIOD} x "
                       f"forcing.frequency, {MIN_SAMPLES_PER_PERIOD * rig.frequency:.6g} to "
                       f"{MAX_SAMPLES_PER_PERIOD * rig.frequency:.6g} Hz")
    if rig.structure is None and (not 1e-100 < p.amplitude < 1e100
                                  or p.zeta * p.period > 300.0):
        raise RigError(f"forcing.frequency={doc['forcing']['frequency']!r} is invalid: the "
                       f"model's omega = {p.omega:.6g} is outside the computable range")
    # the design's delay limit (docs/theory_delay.md, 2): the pulse acts before the
    # grazing phase tau* of the next period, T - pi2_offset / omega after the section
    limit = (p.period - p.pi2_offset / p.omega) / rig.omega_n
    if not rig.budget + w / 2.0 < limit:
        raise RigError(f"controller.budget={doc['controller']['budget']!r} is invalid: the "
                       f"pulse's end, budget + pulse_width / 2 = {rig.budget + w / 2:.6g} s, "
                       f"must come before the grazing phase of the next period, "
                       f"(T - pi2_offset / omega) / omega_n = {limit:.6g} s after the section "
                       "(a later correction cannot cancel the grazing singularity)")


# ---------------------------------------------------------------------- writing
def rig_to_dict(rig: Rig) -> dict:
    """The rig file's mapping of ``rig`` (every value with its unit, 17 digits: a round
    trip through YAML is exact)."""
    s, a = rig.sensor, rig.actuator
    q = format_quantity
    forcing = {"type": rig.forcing,
               "amplitude": q(rig.amplitude, "force" if rig.forcing == "force" else "length"),
               "frequency": q(rig.frequency, "frequency"), "phase": q(rig.phase, "angle")}
    if rig.forcing == "base":
        forcing["stop"] = "frame"
    sensor = {"rate": q(s.rate, "frequency"), "noise": q(s.noise, "length"),
              "resolution": q(s.resolution, "length"), "latency": q(s.latency, "time"),
              "measures": "position_velocity" if s.velocity else "position"}
    if s.velocity:
        sensor["velocity_noise"] = f"{s.velocity_noise:.17g} m/s"
    actuator = {"pulse_width": q(a.pulse_width, "time"),
                "force_limit": q(a.force_limit, "force"), "latency": q(a.latency, "time")}
    if a.force_constant > 0.0:
        actuator["force_constant"] = q(a.force_constant, "force_constant")
    if a.bandwidth > 0.0:
        actuator["bandwidth"] = q(a.bandwidth, "frequency")
    out = {"mass": q(rig.mass, "mass"),
           "natural_frequency": q(rig.natural_frequency, "frequency"),
           "damping_ratio": rig.zeta, "restitution": rig.restitution,
           "gap": q(rig.gap, "length"), "forcing": forcing, "sensor": sensor,
           "actuator": actuator,
           "controller": {"budget": q(rig.budget, "time"),
                          "pi2_offset": q(rig.pi2_offset, "angle")}}
    st = rig.stop
    if st.type != "rigid":
        hertz = st.type == "hertz"
        out["stop"] = {"type": st.type,
                       "stiffness": q(st.stiffness, "hertz_stiffness" if hertz else "stiffness"),
                       "damping": q(st.damping, "hertz_damping" if hertz else "damping"),
                       "friction": q(st.friction, "force"),
                       "friction_static": q(st.friction_static, "force")}
    if rig.structure is not None:
        write_structure(rig.structure, out)
    return out


def rig_with_model(rig: Rig, p) -> Rig:
    """``rig`` with its model replaced by ``p`` (fitted by ``grazing identify``): the
    forcing frequency, amplitude and phase, the mass, sensor and actuator are what the
    lab set and stay; the natural frequency is f / omega, the damping ratio zeta, the
    restitution r, and the gap (Delta d + d*) l with the new length scale l = F0 / k.
    For a rig of n masses ``p`` is an NdofModel (:func:`~grazing_control.plant.rig_structure.rig_with_ndof_model`)."""
    if isinstance(p, NdofModel):
        return rig_with_ndof_model(rig, p)
    omega_n = TWO_PI * rig.frequency / p.omega
    new = replace(rig, omega_n=omega_n, zeta=p.zeta, restitution=p.r,
                  pi2_offset=p.pi2_offset)
    return replace(new, gap=p.d * new.scales.length)
