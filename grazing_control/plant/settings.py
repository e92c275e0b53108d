"""The simulator's parameters: one table (name, type, default, range, doc) and their validation.

:data:`PARAMETERS` is the single source of the sim node's simulation parameters: the
node declares each of them from it (type, default, description, range, read-only) and
validates a set of values with :func:`settings_from_values`, which returns the frozen
:class:`SimSettings` the engine runs on, or raises :class:`ParameterError` naming the bad
parameter and its valid range (nothing half-applied: the caller keeps its old settings).

The model parameters (zeta, r, omega, delta_d, tau0, pi2_offset) are validated by
:class:`grazing_control.oscillator.params.OscillatorParams` (spec section 1); the
actuation delay is the one of docs/theory_delay.md (0 <= delay < T); the injected faults
are :class:`grazing_control.plant.faults.FaultModel`'s (issue 8 section 3).

With ``model_file`` (a YAML model of docs/ndof_model.md; issues 17, 32) the same table
and the same :class:`SimSettings` describe an n-DOF scene: :func:`settings_from_values`
loads the model (``delta_d``, when given, replaces the file's: ``grazing run
--delta-d``) into :attr:`SimSettings.model`, and validates everything that is not the
model -- mode, time scale, state stream period, timeouts, max periods, actuation delay,
loss, jitter, the velocity and measurement noise, seeds, the sensor, the force pulse and
the first-order actuator -- with the model's forcing frequency, so that every bound on a
time reads the n-DOF period T = 2 pi / omega; its start is ``state0``, the 2n coordinates
(:func:`grazing_control.oscillator.ndof.section.start_state`). What an n-DOF scene does
not build (yet) is refused with one line naming the parameter and why, never
half-applied (:data:`NOT_WITH_MODEL_FILE`): the 1-DOF model parameters (the file gives
them), the 1-DOF start x0, v0, the compliant stop and friction, and fidelities other
than exact; the drifting wall (``delta_d_drift``) moves the model's Delta d. The
engine runs either over one interface (:mod:`grazing_control.plant.engine`).
"""

from __future__ import annotations

import dataclasses
import math
import struct
import sys
from dataclasses import dataclass
from functools import cached_property
from typing import NamedTuple

import numpy as np

from grazing_control.dynamics.simulation.actuator import IDEAL_ACTUATOR, Actuator
from grazing_control.dynamics.simulation.fidelity import FIDELITIES
from grazing_control.oscillator.ndof.flow import grazing_clearance
from grazing_control.oscillator.ndof.model import NdofModel, load_model_file
from grazing_control.oscillator.ndof.section import start_state
from grazing_control.oscillator.params import OscillatorParams, ParameterError, study_omega
from grazing_control.oscillator.contact import MAX_FRICTION, MAX_STIFFNESS
from grazing_control.plant.contact_plant import CONTACTS, ContactPlant, contact_from_values
from grazing_control.plant.faults import FaultModel
from grazing_control.plant.sensor import EXACT_SENSOR, SensorModel
from grazing_control.plant.watchdog import WatchdogLimits

__all__ = ["Parameter", "PARAMETERS", "SETTING_KEYS", "MODES", "ACTUATIONS", "ON_MISS",
           "MODEL_KEYS", "ABOVE_0", "FINITE", "below", "described_range", "FEASIBILITY",
           "SimSettings", "settings_from_values", "default_values", "initial_deviation",
           "check_live_change", "LIVE_FACTOR", "NOT_WITH_MODEL_FILE", "load_model_file"]

TWO_PI = 2.0 * math.pi
MODES = ("lockstep", "realtime")
#: When a realtime correction acts: at t_k + actuation_delay (scheduled), when it arrives
#: (on_arrival, the original behaviour), or auto: scheduled if actuation_delay > 0 or
#: jitter > 0, else on_arrival. Lockstep always acts at t_k + actuation_delay.
ACTUATIONS = ("auto", "scheduled", "on_arrival")
#: At a deadline miss or a lost answer: the previous answer's prediction, or nothing.
ON_MISS = ("predict", "drop")
MODEL_KEYS = ("zeta", "r", "omega", "delta_d", "tau0", "pi2_offset")
#: Realtime: what the check before the start does when the scene cannot keep its budget
#: (plant.feasibility): refuse to start (status 2), warn and start, or skip the check.
FEASIBILITY = ("refuse", "warn", "off")
_WD = WatchdogLimits()

#: The closed ranges a ROS descriptor states (FloatingPointRange: both ends included)
#: for the open and the finite bounds of the validation: a bound "> 0" is the least
#: double above 0, a bound "< x" the double :func:`below` x, "finite" the largest finite
#: double (issue 27: ``ros2 param describe`` said [0, 1] for 0 < zeta < 1, and [0, inf]
#: where the node refuses inf).
ABOVE_0 = math.nextafter(0.0, 1.0)
FINITE = sys.float_info.max
#: The largest actuator_bandwidth (tau_a >= 1e-12: faster is the ideal actuator).
MAX_BANDWIDTH = 1e12


def below(x: float) -> float:
    """The largest double below ``x``: the closed end of an open bound ``< x``."""
    return math.nextafter(x, -math.inf)


class Parameter(NamedTuple):
    """One node parameter: ``kind`` is double, integer, string or bool; ``lo``/``hi`` the
    closed range a ROS descriptor states, exactly the values :func:`settings_from_values`
    accepts (None: no range; :func:`described_range` narrows it by the parameters
    declared before), ``choices`` the valid strings, ``read_only`` whether it may change
    while the node runs, ``constraints`` what a range cannot say (a double that may be
    NaN, a bound set by another parameter)."""

    name: str
    kind: str
    default: object
    doc: str
    lo: float | None = None
    hi: float | None = None
    choices: tuple = ()
    read_only: bool = False
    constraints: str = ""


_REF = OscillatorParams()

#: The simulation parameters of sim_node, in declaration order (docs/nodes.md).
PARAMETERS = (
    Parameter("zeta", "double", _REF.zeta, "damping ratio zeta, 0 < zeta < 1", ABOVE_0,
              below(1.0)),
    Parameter("r", "double", _REF.r, "coefficient of restitution r, 0 < r < 1",
              ABOVE_0, below(1.0)),
    Parameter("omega", "double", study_omega(), "forcing frequency omega > 0 (nondimensional)",
              ABOVE_0, FINITE, constraints="actuation_delay < T = 2 pi / omega"),
    Parameter("delta_d", "double", 0.0,
              "wall clearance Delta d = d - d* (< 0: impacting side)", -FINITE, FINITE),
    Parameter("tau0", "double", 0.0, "forcing phase tau0 (reduced mod 2 pi; the sampled "
              "dynamics start on Pi2 and do not depend on it)", -FINITE, FINITE),
    Parameter("pi2_offset", "double", _REF.pi2_offset,
              "phase of Pi2 after Pi1, 0 < pi2_offset < 2 pi (study: pi/2)", ABOVE_0,
              below(TWO_PI)),
    Parameter("x0", "double", math.nan, "initial position on Pi2; NaN = x** (grazing point)",
              constraints="finite and x0 <= d (not beyond the wall), or NaN"),
    Parameter("v0", "double", math.nan, "initial velocity on Pi2; NaN = v** (grazing point)",
              constraints="finite, or NaN"),
    Parameter("state0", "double_array", (), "with model_file: the initial physical state on "
              "Pi2 of the n coordinates, [x_0..x_{n-1}, v_0..v_{n-1}] (2n values); empty = "
              "X** (the grazing point); a 1-DOF scene starts at x0, v0 (empty)",
              constraints="empty, or 2n finite values with the wall coordinate's position "
              "x_{i_w} <= d (not beyond the wall)"),
    Parameter("mode", "string", "lockstep", "lockstep (wait for each correction) or realtime "
              "(paced to the wall clock)", choices=MODES, read_only=True),
    Parameter("time_scale", "double", 1.0,
              "realtime: simulation seconds per wall second, > 0", ABOVE_0, FINITE),
    Parameter("state_period", "double", 1.0, "simulation time between oscillator/state "
              "messages; 0 disables them", 0.0, FINITE),
    Parameter("answer_timeout", "double", 1.0, "lockstep: wall seconds to wait for the "
              "correction of a sample, then apply none", ABOVE_0, FINITE),
    Parameter("max_periods", "integer", 0, "forcing periods to simulate; 0 = unbounded", 0),
    Parameter("fidelity", "string", "exact", "model fidelity: exact (closed-form flow), zdm2 / "
              "zdm1 (normal-form maps), ode (solve_ivp, comparison); lockstep only for all "
              "but exact", choices=FIDELITIES),
    Parameter("noise", "double", 0.0,
              "std of Gaussian velocity noise added at each Pi2 sample", 0.0, FINITE),
    Parameter("seed", "integer", 0, "seed of the noise generator, >= 0 (applied at start and "
              "reset)", 0),
    Parameter("actuation_delay", "double", 0.0,
              "simulation time from a Pi2 sample to its correction, 0 <= actuation_delay < T "
              "(the controller YAML's actuation_delay)", 0.0, FINITE, read_only=True,
              constraints="actuation_delay < T = 2 pi / omega; 0 with a fidelity other than "
              "exact; > 0 in realtime with actuation scheduled (unless jitter or "
              "pulse_width > 0)"),
    Parameter("actuation", "string", "auto",
              "realtime: scheduled (act at t_k + actuation_delay; a later answer is a "
              "deadline miss), on_arrival (act when the answer arrives), auto (scheduled if "
              "actuation_delay or jitter > 0)", choices=ACTUATIONS, read_only=True),
    Parameter("loss", "double", 0.0, "injected fault: probability that a correction is "
              "dropped, 0..1 (FaultModel, seed)", 0.0, 1.0, read_only=True),
    Parameter("measurement_noise", "double", 0.0,
              "injected fault: std of Gaussian noise on the x and v of the published Pi2 "
              "sample (FaultModel, seed)", 0.0, FINITE, read_only=True),
    Parameter("jitter", "double", 0.0,
              "injected fault: std of the actuation time around actuation_delay, simulation "
              "time (FaultModel, seed)", 0.0, FINITE, read_only=True,
              constraints="0 with a fidelity other than exact, or with actuation on_arrival "
              "in realtime"),
    Parameter("on_miss", "string", "predict",
              "when a scheduled correction misses its deadline or is lost: predict (apply "
              "the prediction the previous answer carried for this sample, twist.linear.y) "
              "or drop (apply none)", choices=ON_MISS, read_only=True),
    Parameter("sensor_noise", "double", 0.0,
              "std of the Gaussian noise on each oscillator/state sample's position, and "
              "velocity where carried (SensorModel, sensor_seed)", 0.0, FINITE, read_only=True),
    Parameter("sensor_velocity", "bool", True, "oscillator/state carries the velocity (false: "
              "position only, velocity empty)", read_only=True),
    Parameter("sensor_quantum", "double", 0.0, "quantisation step of the measured position, "
              ">= 0 (0: none)", 0.0, FINITE, read_only=True),
    Parameter("sensor_bias", "double", 0.0, "bias added to the measured position",
              -FINITE, FINITE, read_only=True),
    Parameter("delta_d_drift", "double", 0.0, "linear drift of the plant's Delta d per "
              "forcing period (a wearing stop, a warming rig; issue 29): sample k's period "
              "runs with the Delta d in force plus delta_d_drift * (k - k0), k0 the sample "
              "where it was set or reset; 0 = none", -FINITE, FINITE, read_only=True,
              constraints="|delta_d_drift| <= d*, the non-impacting amplitude at the wall"),
    Parameter("pre_roll", "integer", 0, "realtime, scheduled: the stream's pre-roll, the "
              "first pre_roll sections have no deadline: the stream runs, nothing acts there "
              "and an answer to them is counted as unarmed, not late (a section's answer is "
              "estimated from the period before it, which a stream starting at section 0 "
              "does not have: docs/driver_contract.md, 'Pre-roll'); a rig_file's default 1, "
              ">= 0", 0, read_only=True),
    Parameter("sensor_seed", "integer", 0, "seed of the sensor noise, >= 0 (draws a pure "
              "function of (sensor_seed, sample index))", 0, read_only=True),
    Parameter("pulse_width", "double", 0.0,
              "actuation as a force pulse of this width (simulation time) centred at the "
              "actuation time, impulse = the commanded Delta v; 0 = the velocity jump",
              0.0, FINITE, read_only=True,
              constraints="pulse_width <= 2 actuation_delay and actuation_delay + "
              "pulse_width / 2 < T; 0 with a fidelity other than exact, or with actuation "
              "on_arrival in realtime"),
    Parameter("force_limit", "double", 0.0, "largest |force| of a pulse, > 0; 0 = no limit "
              "(the impulse delivered is then smaller than commanded)", 0.0, FINITE,
              read_only=True),
    Parameter("actuator_bandwidth", "double", 0.0, "a first-order actuator between the "
              "commanded correction and the force (issue 29): its bandwidth 1 / tau_a, "
              "radians per simulation time unit (N x the forcing frequency is N omega); 0 = "
              "ideal (the force follows the command at once); <= 1e12", 0.0,
              MAX_BANDWIDTH, read_only=True,
              constraints="0 or >= 1 / the largest double (tau_a finite); 0 with a fidelity "
              "other than exact, or with actuation on_arrival in realtime"),
    Parameter("actuator_latency", "double", 0.0, "the actuator's latency L from the "
              "command to the force, simulation time, >= 0 (0: none)", 0.0, FINITE,
              read_only=True, constraints="the command ends within the period: "
              "actuation_delay + pulse_width / 2 + actuator_latency < T; 0 with a fidelity "
              "other than exact, or with actuation on_arrival in realtime"),
    Parameter("watchdog_window", "integer", _WD.window, "realtime watchdog "
              "(plant.watchdog): samples of its sliding window, 1..1000000", 1, 1_000_000,
              read_only=True),
    Parameter("watchdog_misses", "integer", _WD.misses, "realtime watchdog: stop actuating "
              "and fail the scene at this many samples without an answer in time within "
              "the window, 0..1000000 (0 = off; more than the window: never)", 0, 1_000_000,
              read_only=True),
    Parameter("watchdog_pace", "double", _WD.pace, "realtime watchdog: ... when the "
              "simulation ran slower than this fraction of time_scale over a full window, "
              "0..1 (0 = off)", 0.0, 1.0, read_only=True),
    Parameter("watchdog_lag", "double", _WD.lag, "realtime watchdog: ... when a sample "
              "goes out more than this many wall seconds late, >= 0 (0 = off)", 0.0,
              FINITE, read_only=True),
    Parameter("watchdog_excursion", "double", _WD.excursion, "realtime watchdog: ... when, "
              "while corrections act, the Pi2 state is farther from X** than this many "
              "times sqrt(|delta_d|), >= 0 (0 = off)", 0.0, FINITE, read_only=True),
    Parameter("feasibility", "string", "refuse", "realtime: before the start, the "
              "controller's measured round trip against the budget (actuation delay / "
              "time_scale) and the simulation rate this machine sustains against the "
              "requested one (plant.feasibility): refuse (exit status 2), warn, or off",
              choices=FEASIBILITY, read_only=True),
    Parameter("contact", "string", "rigid", "the stop (issue 31, plant.contact_plant): rigid "
              "(the wall, restitution r), kelvin_voigt (spring-dashpot) or hertz "
              "(Hunt-Crossley); compliant stops with the exact fidelity (and any actuator: "
              "the first-order one's force is in the stop's flow)",
              choices=CONTACTS, read_only=True,
              constraints="rigid unless fidelity exact"),
    Parameter("contact_stiffness", "double", 1e6, "compliant stop: stiffness k_c over the "
              "oscillator's (hertz: force per penetration^1.5), 0 < k_c <= 1e18", ABOVE_0,
              MAX_STIFFNESS,
              read_only=True),
    Parameter("contact_damping", "double", 0.0, "compliant stop: damping c_c over m omega_n "
              "(kelvin_voigt, c_c < 2 sqrt(k_c)) or Hunt-Crossley alpha (hertz), >= 0",
              0.0, FINITE, read_only=True,
              constraints="kelvin_voigt: (2 zeta + c_c)^2 < 4 (1 + k_c) and c_c < 2 sqrt(k_c)"),
    Parameter("friction", "double", 0.0, "Coulomb dry friction on the mass, kinetic level "
              "F_f (force over k l), 0..1e6; 0 = none", 0.0, MAX_FRICTION, read_only=True,
              constraints="0 with contact rigid"),
    Parameter("friction_static", "double", 0.0, "static friction level F_s >= friction; "
              "0 = friction", 0.0, MAX_FRICTION, read_only=True,
              constraints="0 or >= friction"),
)

SETTING_KEYS = tuple(p.name for p in PARAMETERS)


def default_values() -> dict:
    """{name: default} of :data:`PARAMETERS` (what a node without overrides starts with)."""
    return {p.name: p.default for p in PARAMETERS}


def described_range(p: Parameter, declared: dict) -> tuple:
    """(lo, hi): the closed range ``ros2 param describe`` states for ``p``, given the
    values ``declared`` before it (the node declares :data:`PARAMETERS` in order).

    The table's range, narrowed where another parameter bounds it, so that with the
    others at these values :func:`settings_from_values` accepts exactly [lo, hi]:
    friction and friction_static 0 with contact rigid; |delta_d_drift| <= d* (_drift);
    actuation_delay < T = 2 pi / omega, and 0 without the exact flow; jitter and the
    actuator 0 without the exact flow or with actuation on_arrival in realtime;
    pulse_width <= 2 actuation_delay and actuation_delay + pulse_width / 2 < T, 0 where
    jitter is; actuation_delay + pulse_width / 2 + actuator_latency < T.
    Where the model declared is invalid, the table's range (the model is refused by
    name anyway).
    """
    if p.name in ("friction", "friction_static"):   # Coulomb friction: a compliant stop's
        return (p.lo, p.hi) if declared.get("contact", "rigid") != "rigid" else (p.lo, 0.0)
    if p.name == "delta_d_drift":        # |drift| <= d* of the model declared (_drift)
        try:
            d_star = OscillatorParams(**{k: declared[k] for k in MODEL_KEYS}).d_star
        except (KeyError, TypeError, ParameterError):
            return p.lo, p.hi
        return -d_star, d_star
    if p.name not in ("actuation_delay", "jitter", "pulse_width", "actuator_bandwidth",
                      "actuator_latency"):
        return p.lo, p.hi
    try:
        period = OscillatorParams(**{k: declared[k] for k in MODEL_KEYS}).period
    except (KeyError, TypeError, ParameterError):
        return p.lo, p.hi
    exact = declared.get("fidelity", "exact") == "exact"
    if p.name == "actuation_delay":
        return p.lo, below(period) if exact else 0.0
    on_arrival = declared.get("mode") == "realtime" and declared.get("actuation") == "on_arrival"
    if not exact or on_arrival:
        return p.lo, 0.0
    if p.name in ("jitter", "actuator_bandwidth"):
        return p.lo, p.hi
    delay = declared.get("actuation_delay", 0.0)
    if p.name == "actuator_latency":
        return p.lo, _last_fitting(lambda latency: 0.0 <= delay + declared.get(
            "pulse_width", 0.0) / 2.0 + latency < period, FINITE)
    if not 0.0 < delay < period:
        return p.lo, 0.0

    return p.lo, _last_fitting(lambda w: _pulse_fits(w, delay, period), min(2.0 * delay,
                                                                            FINITE))


def _last_fitting(fits, top: float) -> float:
    """The last double in [0, top] that ``fits`` (0 fits, and fitting is monotone):
    bisection over the doubles, whose bit patterns are ordered as their values."""
    lo, hi = 0, _bits(top)
    while lo < hi:
        mid = (lo + hi + 1) // 2
        lo, hi = (mid, hi) if fits(_double(mid)) else (lo, mid - 1)
    return _double(lo)


def _pulse_fits(width: float, delay: float, period: float) -> bool:
    """A pulse of ``width`` centred at ``delay`` lies within the period: it starts at or
    after the sample (width <= 2 delay; not width / 2 <= delay, which a subnormal width
    passes with delay 0) and ends before the next one (delay + width / 2 < T)."""
    return width <= 2.0 * delay and delay + width / 2.0 < period


def _bits(x: float) -> int:
    """The bit pattern of a double >= 0, as an integer (ordered as the doubles)."""
    return struct.unpack("<q", struct.pack("<d", x))[0]


def _double(bits: int) -> float:
    """The double >= 0 of a bit pattern (:func:`_bits`)."""
    return struct.unpack("<d", struct.pack("<q", bits))[0]


@dataclass(frozen=True)
class SimSettings:
    """The sim node's validated parameters (see :func:`settings_from_values`)."""

    params: OscillatorParams
    x0: float
    v0: float
    mode: str
    time_scale: float
    state_period: float
    answer_timeout: float
    max_periods: int
    fidelity: str
    noise: float
    seed: int
    actuation_delay: float = 0.0
    actuation: str = "auto"
    loss: float = 0.0
    measurement_noise: float = 0.0
    jitter: float = 0.0
    on_miss: str = "predict"
    sensor: SensorModel = EXACT_SENSOR
    pulse_width: float = 0.0
    force_limit: float = 0.0
    watchdog: WatchdogLimits = WatchdogLimits()
    feasibility: str = "refuse"
    delta_d_drift: float = 0.0
    pre_roll: int = 0
    actuator: Actuator = IDEAL_ACTUATOR
    contact: ContactPlant | None = None
    #: an n-DOF scene's model (with the scene's delta_d) and its file; None: the study's
    #: 1-DOF oscillator of ``params`` (in an n-DOF scene ``params`` is the 1-DOF default
    #: with the model's forcing frequency: only its period is read)
    model: NdofModel | None = None
    model_file: str = ""
    #: an n-DOF scene's initial physical state on Pi2 (2n values; () = X**)
    state0: tuple = ()

    @property
    def delta_d(self) -> float:
        """The plant's Delta d: the n-DOF model's, else the 1-DOF parameters'."""
        return self.params.delta_d if self.model is None else self.model.delta_d

    @property
    def scheduled(self) -> bool:
        """Realtime corrections act at t_k + actuation_delay (else on arrival)."""
        if self.actuation == "auto":
            return self.actuation_delay > 0.0 or self.jitter > 0.0
        return self.actuation == "scheduled"

    def describe(self) -> str:
        """One line for the node's start-up log: the model file (n-DOF), mode, scene,
        actuation, faults."""
        m = self.model
        text = "" if m is None else (f"model_file={self.model_file} n={m.n} i_w={m.i_w} "
                                     f"i_a={m.i_a} ")
        if self.state0:
            text += f"state0={list(self.state0)!r} "
        text += (f"mode={self.mode} delta_d={self.delta_d!r} "
                f"max_periods={self.max_periods} state_period={self.state_period} "
                f"actuation={'scheduled' if self.scheduled else 'on_arrival'} "
                f"actuation_delay={self.actuation_delay!r}")
        if not self.sensor.exact or not self.sensor.velocity:
            sn = self.sensor
            text += (f" sensor noise={sn.noise!r} velocity={str(sn.velocity).lower()} "
                     f"quantum={sn.quantum!r} bias={sn.bias!r} seed={sn.seed}")
        if self.delta_d_drift != 0.0:
            text += f" delta_d_drift={self.delta_d_drift!r}"
        if self.pre_roll and self.scheduled:
            text += f" pre_roll={self.pre_roll}"
        if self.contact is not None:
            text += f" contact={self.contact.law!r} friction={self.contact.friction!r}"
        if self.pulse_width > 0.0:
            text += f" pulse_width={self.pulse_width!r} force_limit={self.force_limit!r}"
        if not self.actuator.ideal:
            bw = self.actuator.time_constant
            text += (f" actuator_bandwidth={1.0 / bw if bw else 0.0!r} "
                     f"actuator_latency={self.actuator.latency!r}")
        if self.faults.active:
            text += (f" faults loss={self.loss!r} measurement_noise="
                     f"{self.measurement_noise!r} jitter={self.jitter!r} seed={self.seed}")
        return text

    @cached_property
    def faults(self) -> FaultModel:
        """The injected faults (loss, measurement noise, jitter) with the node's seed."""
        return FaultModel(self.loss, self.measurement_noise, self.jitter, self.seed)


def _finite(name, value, ok, valid):
    value = float(value)
    if not (math.isfinite(value) and ok(value)):
        raise ParameterError(f"{name}={value!r} is invalid: valid range is {valid}")
    return value


def _drift(value, d_star) -> float:
    """delta_d_drift, |value| <= d* = ``d_star()`` (docs/nodes.md; 1e308 overflowed)."""
    if (value := float(value)) == 0.0:
        return value
    d = d_star()
    return _finite("delta_d_drift", value, lambda v: abs(v) <= d,
                   f"|delta_d_drift| <= d* = {d!r} per forcing period (d*: the amplitude of "
                   "the wall coordinate's non-impacting motion)")


def settings_from_values(values: dict, model_file: str = "",
                         model: NdofModel | None = None) -> SimSettings:
    """Validate the sim node's parameter values; raise ParameterError naming the bad one.

    ``values`` maps names of :data:`PARAMETERS` to values; a name left out takes its
    default. The model parameters go through :class:`OscillatorParams` (its message names
    the parameter and its range, spec section 1); the initial state must be finite or NaN
    (= X**) and not beyond the wall (x0 <= d). With ``model_file`` an n-DOF scene
    (module docstring; ``model``: the file's model when already loaded, ``delta_d`` left
    out: the file's).
    """
    if model_file:
        return _model_file_settings(values, model_file, model)
    values = {**default_values(), **values}
    p = OscillatorParams(**{k: values[k] for k in MODEL_KEYS})
    mode = str(values["mode"])
    if mode not in MODES:
        raise ParameterError(f"mode={mode!r} is invalid: valid values are {', '.join(MODES)}")
    fidelity = str(values["fidelity"])
    if fidelity not in FIDELITIES:
        raise ParameterError(
            f"fidelity={fidelity!r} is invalid: valid values are {', '.join(FIDELITIES)}")
    if fidelity != "exact" and mode == "realtime":
        raise ParameterError(
            f"fidelity={fidelity!r} is invalid in realtime mode: valid there is 'exact' only "
            "(corrections land inside a period, which only the exact flow can split)")
    x0, v0 = float(values["x0"]), float(values["v0"])
    for name, value in (("x0", x0), ("v0", v0)):
        if math.isinf(value):
            raise ParameterError(f"{name}={value!r} is invalid: valid range is a finite real "
                                 "number, or NaN for the grazing point X**")
    if not math.isnan(x0) and x0 > p.d:
        raise ParameterError(f"x0={x0!r} is invalid: valid range is x0 <= d = {p.d!r} "
                             "(the state must not be beyond the wall)")
    if values["state0"] is not None and len(values["state0"]) > 0:
        raise ParameterError(f"state0={list(values['state0'])!r} is invalid without "
                             "model_file: valid is empty (a 1-DOF scene starts at x0, v0)")
    max_periods = int(values["max_periods"])
    if max_periods < 0:
        raise ParameterError(f"max_periods={max_periods} is invalid: valid range is >= 0 "
                             "(0 = unbounded)")
    seed = int(values["seed"])
    if seed < 0:
        raise ParameterError(f"seed={seed} is invalid: valid range is seed >= 0")
    pre_roll = int(values["pre_roll"])
    if pre_roll < 0:
        raise ParameterError(f"pre_roll={pre_roll} is invalid: valid range is pre_roll >= 0 "
                             "(sections without a deadline at the stream's start)")
    actuation = _actuation_values(values, p, mode, fidelity)
    contact = _contact(values, p, mode, fidelity, actuation)
    return SimSettings(
        params=p, x0=x0, v0=v0, mode=mode,
        time_scale=_finite("time_scale", values["time_scale"], lambda v: v > 0.0,
                           "a finite time_scale > 0"),
        state_period=_finite("state_period", values["state_period"], lambda v: v >= 0.0,
                             "a finite state_period >= 0 (0 disables oscillator/state)"),
        answer_timeout=_finite("answer_timeout", values["answer_timeout"],
                               lambda v: v > 0.0, "a finite answer_timeout > 0"),
        max_periods=max_periods, fidelity=fidelity,
        noise=_finite("noise", values["noise"], lambda v: v >= 0.0, "a finite noise >= 0"),
        seed=seed, sensor=_sensor(values), watchdog=_watchdog(values),
        feasibility=_choice(values, "feasibility", FEASIBILITY),
        delta_d_drift=_drift(values["delta_d_drift"], lambda: p.d_star),
        pre_roll=pre_roll, contact=contact, **actuation)


#: The table's values an n-DOF scene refuses unless left at their defaults, and why.
NOT_WITH_MODEL_FILE = {
    "zeta": "the model file gives the n-DOF model (M, C, K, f, omega, r, phase, pi2_offset)",
    "r": "the model file gives the coefficient of restitution",
    "omega": "the model file gives the forcing frequency",
    "tau0": "the model file gives the forcing phase",
    "pi2_offset": "the model file gives pi2_offset",
    "x0": "an n-DOF scene's start is state0, its 2n coordinates (empty: X**)",
    "v0": "an n-DOF scene's start is state0, its 2n coordinates (empty: X**)",
    "fidelity": "only the exact flow is built for n-DOF",
    "contact": "the compliant stop is not built for n-DOF (the rigid wall only)",
    "contact_stiffness": "the compliant stop is not built for n-DOF (the rigid wall only)",
    "contact_damping": "the compliant stop is not built for n-DOF (the rigid wall only)",
    "friction": "dry friction is not built for n-DOF",
    "friction_static": "dry friction is not built for n-DOF",
}


def _model_file_settings(values: dict, model_file: str, model: NdofModel | None) -> SimSettings:
    """The settings of an n-DOF scene (module docstring): the file's model with the scene's
    delta_d, the rest validated as the 1-DOF table's with the model's omega."""
    model = load_model_file(model_file) if model is None else model
    defaults = default_values()
    for name, why in NOT_WITH_MODEL_FILE.items():
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
    state0 = start_state(values.get("state0"), model)
    rest = {k: v for k, v in values.items()
            if k not in MODEL_KEYS and k not in NOT_WITH_MODEL_FILE and k != "state0"}
    # the 1-DOF validation with the n-DOF forcing frequency: its bounds on times read T
    base = settings_from_values({**rest, "omega": model.omega, "delta_d_drift": 0.0})
    drift = _drift(values.get("delta_d_drift", 0.0), lambda: grazing_clearance(model))
    if not base.actuator.ideal and base.pulse_width == 0.0:
        raise ParameterError("pulse_width=0.0 is invalid with model_file and the first-order "
                             "actuator (actuator_bandwidth, actuator_latency): valid range is "
                             "pulse_width > 0 (the n-DOF actuator's command is a pulse: "
                             "modal_map.actuated_step)")
    if base.pulse_width > 0.0:     # a force pulse needs the static deflection K^-1 e_a
        from grazing_control.oscillator.ndof.flow import NdofFlow
        from grazing_control.oscillator.ndof.forced import static_deflection

        try:
            static_deflection(NdofFlow.of(model))
        except ParameterError as exc:
            raise ParameterError(f"pulse_width={base.pulse_width!r} is invalid with model_file="
                                 f"{model_file!r}: valid is 0 ({exc})") from None
    return dataclasses.replace(base, model=model, model_file=str(model_file), state0=state0,
                               delta_d_drift=drift)


def _same(value, default) -> bool:
    """Whether a parameter value is its default (NaN equals NaN)."""
    if isinstance(default, float) and isinstance(value, (int, float)) and not isinstance(
            value, bool):
        return float(value) == default or (math.isnan(default) and math.isnan(float(value)))
    return value == default


def _contact(values: dict, p: OscillatorParams, mode: str, fidelity: str,
             actuation: dict) -> ContactPlant | None:
    """The compliant stop and friction (plant.contact_plant). The engine runs it wherever
    it runs the wall's exact flow (lockstep and realtime, a delayed, jittered or split
    correction, a force pulse, the drifting wall, the sensor stream: its pieces are the
    stop's flow, docs/theory_contact.md §16), the first-order actuator included (its force
    F_inf + C e^{-h / tau_a} in the stop's flow, §21). Refused in one line: a fidelity
    other than exact (the cheaper fidelities are approximations of the rigid wall's impact
    map, which a compliant stop has not)."""
    contact = contact_from_values(values, p)
    if contact is None:
        return None
    if fidelity != "exact":
        raise ParameterError(f"fidelity={fidelity!r} is invalid with contact="
                             f"{values['contact']!r}: valid there is 'exact' (the other "
                             "fidelities approximate the rigid wall's impact map)")
    return contact


def _choice(values: dict, name: str, choices: tuple) -> str:
    value = str(values[name])
    if value not in choices:
        raise ParameterError(f"{name}={value!r} is invalid: valid values are "
                             f"{', '.join(choices)}")
    return value


def _watchdog(values: dict) -> WatchdogLimits:
    """The realtime watchdog's thresholds (plant.watchdog), each in its range."""
    ints = {}
    for name, lo in (("watchdog_window", 1), ("watchdog_misses", 0)):
        value = values[name]
        if (isinstance(value, bool) or not isinstance(value, (int, np.integer))
                or not lo <= value <= 1_000_000):
            raise ParameterError(f"{name}={value!r} is invalid: valid range is an integer "
                                 f"{lo}..1000000" + (" (0 = off)" if lo == 0 else ""))
        ints[name] = int(value)
    return WatchdogLimits(
        window=ints["watchdog_window"], misses=ints["watchdog_misses"],
        pace=_finite("watchdog_pace", values["watchdog_pace"], lambda v: 0.0 <= v <= 1.0,
                     "0 <= watchdog_pace <= 1 (0 = off)"),
        lag=_finite("watchdog_lag", values["watchdog_lag"], lambda v: v >= 0.0,
                    "a finite watchdog_lag >= 0 wall seconds (0 = off)"),
        excursion=_finite("watchdog_excursion", values["watchdog_excursion"],
                          lambda v: v >= 0.0, "a finite watchdog_excursion >= 0 (0 = off)"))


def _sensor(values: dict) -> SensorModel:
    """The rig's motion sensor of the state stream (plant.sensor.SensorModel)."""
    seed = values["sensor_seed"]
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise ParameterError(f"sensor_seed={seed!r} is invalid: valid range is an integer >= 0")
    velocity = values["sensor_velocity"]
    if not isinstance(velocity, bool):
        raise ParameterError(f"sensor_velocity={velocity!r} is invalid: valid values are "
                             "true, false")
    return SensorModel(noise=values["sensor_noise"], velocity=velocity,
                       quantum=values["sensor_quantum"], bias=values["sensor_bias"],
                       seed=int(seed))


def _actuation_values(values: dict, p: OscillatorParams, mode: str, fidelity: str) -> dict:
    """Validate actuation_delay, actuation and the injected faults (docs/nodes.md)."""
    out = {
        "actuation_delay": _finite(
            "actuation_delay", values["actuation_delay"],
            lambda v: 0.0 <= v < p.period,
            f"0 <= actuation_delay < T = {p.period!r} (simulation time)"),
        "loss": _finite("loss", values["loss"], lambda v: 0.0 <= v <= 1.0, "0 <= loss <= 1"),
        "measurement_noise": _finite("measurement_noise", values["measurement_noise"],
                                     lambda v: v >= 0.0, "a finite measurement_noise >= 0"),
        "jitter": _finite("jitter", values["jitter"], lambda v: v >= 0.0,
                          "a finite jitter >= 0 (simulation time)"),
    }
    out["pulse_width"] = w = _finite(
        "pulse_width", values["pulse_width"], lambda v: v >= 0.0,
        "a finite pulse_width >= 0 (simulation time; 0: the velocity jump)")
    out["force_limit"] = _finite("force_limit", values["force_limit"], lambda v: v >= 0.0,
                                 "a finite force_limit >= 0 (0: no limit)")
    delay = out["actuation_delay"]
    if w > 0.0 and not _pulse_fits(w, delay, p.period):
        raise ParameterError(
            f"pulse_width={w!r} is invalid with actuation_delay={delay!r}: valid range is "
            "pulse_width <= 2 actuation_delay and actuation_delay + pulse_width / 2 < "
            f"T = {p.period!r} (the pulse is centred at the actuation time, within the "
            "period)")
    out["on_miss"] = str(values["on_miss"])
    if out["on_miss"] not in ON_MISS:
        raise ParameterError(f"on_miss={out['on_miss']!r} is invalid: valid values are "
                             f"{', '.join(ON_MISS)}")
    actuation = str(values["actuation"])
    if actuation not in ACTUATIONS:
        raise ParameterError(f"actuation={actuation!r} is invalid: valid values are "
                             f"{', '.join(ACTUATIONS)}")
    out["actuation"] = actuation
    split = out["actuation_delay"] > 0.0 or out["jitter"] > 0.0 or w > 0.0
    if split and fidelity != "exact":
        raise ParameterError(
            f"fidelity={fidelity!r} is invalid with actuation_delay or jitter > 0: valid "
            "there is 'exact' only (the correction splits the period)")
    if mode == "realtime" and actuation == "on_arrival" and w > 0.0:
        raise ParameterError(f"pulse_width={w!r} is invalid with actuation=on_arrival: valid "
                             "there is 0 (a pulse is centred at a scheduled actuation time)")
    out["actuator"] = _actuator(values, p, mode, actuation, fidelity, delay, w)
    if mode == "realtime" and actuation == "on_arrival" and out["jitter"] > 0.0:
        raise ParameterError(f"jitter={out['jitter']!r} is invalid with actuation=on_arrival: "
                             "valid there is 0 (the actuation time is the arrival)")
    if mode == "realtime" and actuation == "scheduled" and not split:
        raise ParameterError(
            "actuation_delay=0.0 is invalid with actuation=scheduled in realtime mode: valid "
            f"range is 0 < actuation_delay < T = {p.period!r} (no answer can arrive at its "
            "own sample's instant); use actuation:=on_arrival to apply on arrival")
    return out


def _actuator(values: dict, p: OscillatorParams, mode: str, actuation: str, fidelity: str,
              delay: float, w: float) -> Actuator:
    """The first-order actuator of actuator_bandwidth and actuator_latency (0, 0: the
    ideal one): the exact flow only, a scheduled command that ends within the period."""
    bandwidth = _finite("actuator_bandwidth", values["actuator_bandwidth"],
                        lambda v: 0.0 <= v <= MAX_BANDWIDTH, "0 <= actuator_bandwidth <= "
                        "1e12 (radians per simulation time unit; 0: ideal)")
    latency = _finite("actuator_latency", values["actuator_latency"], lambda v: v >= 0.0,
                      "a finite actuator_latency >= 0 (simulation time)")
    if bandwidth == 0.0 and latency == 0.0:
        return IDEAL_ACTUATOR
    name, value = (("actuator_bandwidth", bandwidth) if bandwidth > 0.0
                   else ("actuator_latency", latency))
    if fidelity != "exact":
        raise ParameterError(f"{name}={value!r} is invalid with fidelity={fidelity!r}: valid "
                             "there is 0 (the actuator's flow is the exact one)")
    if mode == "realtime" and actuation == "on_arrival":
        raise ParameterError(f"{name}={value!r} is invalid with actuation=on_arrival: valid "
                             "there is 0 (the actuator acts on a scheduled command)")
    tau_a = 1.0 / bandwidth if bandwidth > 0.0 else 0.0
    if not math.isfinite(tau_a):
        raise ParameterError(f"actuator_bandwidth={bandwidth!r} is invalid: valid range is 0 "
                             "or >= 1 / the largest double (tau_a = 1 / bandwidth finite)")
    end = delay + w / 2.0 + latency
    if not end < p.period:
        raise ParameterError(f"actuator_latency={latency!r} is invalid with actuation_delay="
                             f"{delay!r} and pulse_width={w!r}: valid range is "
                             "actuation_delay + pulse_width / 2 + actuator_latency < "
                             f"T = {p.period!r} (the command ends within the period)")
    return Actuator(tau_a, latency)


def initial_deviation(p: OscillatorParams, x0: float, v0: float) -> tuple:
    """(x0 - x**, v0 - v**) with NaN meaning the grazing point's coordinate: as simulate()."""
    x = p.x_ref if math.isnan(x0) else x0
    v = p.v_ref if math.isnan(v0) else v0
    return x - p.x_ref, v - p.v_ref


#: A live change (``live_changes:=true``) may move zeta, r, omega and time_scale by at most
#: this factor either way: exploring nearby parameters of a running scene, not a new one.
LIVE_FACTOR = 2.0


def check_live_change(old: SimSettings, new: SimSettings, periods_done: int) -> None:
    """Refuse a change, while the scene runs, whose consequences are absurd (issue 21 §3).

    :func:`settings_from_values` has checked each value's own range; here the change is
    checked against the running scene: the free motion's amplitude a (``old.params``) is
    the scale of the model. Refused (ParameterError naming the parameter and the range):

    * ``delta_d`` outside [-a, a] (the wall beyond the whole motion's reach: a state
      placed on a wall a further away is no longer this oscillator);
    * ``zeta``, ``r``, ``omega`` or ``time_scale`` changed by more than LIVE_FACTOR;
    * ``noise``, ``measurement_noise`` or ``sensor_noise`` above a (noise larger than the
      motion itself);
    * ``state_period`` in (0, T/10^4) (over 10^4 state messages per period);
    * ``max_periods`` 0 (unbounded) where it was bounded, or at most ``periods_done``.

    In an n-DOF scene (``old.model``) the scale a is the wall coordinate's amplitude d*
    of the model's periodic response, and a change of the model (its ``delta_d``) is
    refused: a live change of the n-DOF model is not built (the engine would have to
    re-express z on the new model's section, as the 1-DOF engine's pending parameters).
    Static settings (the mode, the actuation, seeds) are read-only while running anyway.
    """
    if old.model is not None:
        if new.delta_d != old.delta_d:   # the file is read-only: its delta_d is the change
            raise ParameterError(
                f"delta_d={new.delta_d!r} is invalid while an n-DOF scene runs: a live change "
                f"of the n-DOF model is not built (valid: {old.delta_d!r}; set it before the "
                "start)")
        a = grazing_clearance(old.model)
    else:
        a = old.params.amplitude
    dd = new.params.delta_d
    if new.params.delta_d != old.params.delta_d and not -a <= dd <= a:
        raise ParameterError(f"delta_d={dd!r} is invalid while the scene runs: valid range is "
                             f"[-{a:.6g}, {a:.6g}] (the free motion's amplitude a)")
    for name, o, n in (("zeta", old.params.zeta, new.params.zeta),
                       ("r", old.params.r, new.params.r),
                       ("omega", old.params.omega, new.params.omega),
                       ("time_scale", old.time_scale, new.time_scale)):
        if n != o and not o / LIVE_FACTOR <= n <= o * LIVE_FACTOR:
            raise ParameterError(
                f"{name}={n!r} is invalid while the scene runs: valid range is "
                f"[{o / LIVE_FACTOR:.6g}, {o * LIVE_FACTOR:.6g}] (within a factor "
                f"{LIVE_FACTOR:g} of the running {o:.6g}; a larger change is a new scene)")
    for name, o, n in (("noise", old.noise, new.noise),
                       ("measurement_noise", old.measurement_noise, new.measurement_noise),
                       ("sensor_noise", old.sensor.noise, new.sensor.noise)):
        if n != o and not n <= a:
            raise ParameterError(f"{name}={n!r} is invalid while the scene runs: valid range "
                                 f"is [0, {a:.6g}] (at most the motion's amplitude a)")
    sp = new.state_period
    period = old.params.period          # an n-DOF scene's: the model's omega (module doc)
    if sp != old.state_period and 0.0 < sp < period * 1e-4:
        raise ParameterError(f"state_period={sp!r} is invalid while the scene runs: valid "
                             f"range is 0 (off) or >= T/1e4 = {period * 1e-4:.6g}")
    mp = new.max_periods
    if mp != old.max_periods and (mp == 0 and old.max_periods != 0 or 0 < mp <= periods_done):
        raise ParameterError(
            f"max_periods={mp!r} is invalid while the scene runs: valid range is > "
            f"{periods_done} (the periods done)" + (", not 0: the scene was bounded"
                                                   if mp == 0 else ""))
