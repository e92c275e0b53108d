"""The rig boundary of the nodes: SI and the rig clock outside, the model's units inside.

The driver contract (docs/driver_contract.md) speaks SI in the rig's own clock; the
simulator and the controller compute in the study's dimensionless units
(:mod:`grazing_control.plant.rig`: tau = omega_n t, x~ = x / l, v~ = v / (omega_n l)).
This module holds the conversions both nodes make at that boundary, with no rclpy in
it (the nodes build the messages):

* :func:`sim_values`: the simulator's parameters that a rig file sets (its model, the
  sensor stream, the pulse, the budget as the actuation delay, the pace);
* :class:`SimulatedClock`: the simulated rig's clock, which starts at ``clock_start``
  seconds (a DAQ that has been running) snapped to the next Pi2 section, and runs at
  ``time_scale / omega_n`` rig seconds per wall second: against ROS time it has an
  offset and the drift omega_n / time_scale - 1 (``clock_drift``), as a real rig's
  clock does;
* :class:`DelayLine`: the sensor's latency (each sample published no earlier than its
  time + latency);
* :class:`Sections`: the controller's side: the section times from ``rig/phase`` (where
  the forcing phase equals tau2), rig time <-> model time, and the pulse's force of a
  correction and back (F = m_a Delta v / w, Delta v = omega_n l Delta v~, m_a the
  actuated mass's effective mass 1 / (M^-1)_aa: the rig's mass for one mass);
* :func:`joint_names`, :func:`sensor_positions`, :func:`model_positions`: the
  ``rig/sensor`` JointState of a rig of n masses (the measured masses' positions in
  metres, named ``mass<i>`` in the rig file's ``sensor.masses`` order; ``mass`` for one
  mass) and back to the model's coordinates.
"""

from __future__ import annotations

import math
from collections import deque

from grazing_control.oscillator.params import ParameterError
from grazing_control.plant.rig import Rig
from grazing_control.plant.settings import default_values

__all__ = ["SIM_KEYS", "CONTROLLER_KEYS", "MASSES_CONTROLLER_KEYS", "sim_values",
           "masses_controller_values", "joint_names", "sensor_positions",
           "model_positions", "controller_values", "answer_lead",
           "check_rig_values", "first_section", "SimulatedClock", "DelayLine", "Pacer",
           "Sections",
           "force_of", "correction_of", "APPLIED_IN_TIME", "APPLIED_PREDICTED",
           "APPLIED_NOTHING", "APPLIED_SAFE", "RIG_TOPICS"]

TWO_PI = 2.0 * math.pi

#: rig/applied's wrench.force.z (docs/driver_contract.md): what acted at a section.
APPLIED_IN_TIME, APPLIED_PREDICTED, APPLIED_NOTHING, APPLIED_SAFE = 0.0, 1.0, 2.0, 3.0

#: The contract's topics (relative names) and types, for the recorder.
RIG_TOPICS = {"rig/sensor": "sensor_msgs/msg/JointState",
              "rig/phase": "geometry_msgs/msg/Vector3Stamped",
              "rig/clock": "sensor_msgs/msg/TimeReference",
              "rig/force_pulse": "geometry_msgs/msg/WrenchStamped",
              "rig/applied": "geometry_msgs/msg/WrenchStamped",
              "grazing/rig": "std_msgs/msg/String"}

#: The simulator's parameters set by a rig file (:func:`sim_values`); ``time_scale``
#: (a faster scene) and ``pre_roll`` may be given, the others are the rig's.
CONTACT_KEYS = ("contact", "contact_stiffness", "contact_damping", "friction",
                "friction_static")
SIM_KEYS = ("zeta", "r", "omega", "delta_d", "tau0", "pi2_offset", "state_period",
            "sensor_noise", "sensor_quantum", "sensor_velocity", "pulse_width",
            "force_limit", "actuator_bandwidth", "actuation_delay", "time_scale", "pre_roll",
            *CONTACT_KEYS)
#: A simulated rig's pre-roll (sim_node's ``pre_roll``): its stream starts at section 0,
#: whose answer cannot be estimated from the period before it (no samples): at physical
#: speed it came 6.3 ms after section 0 against a 5 ms budget, a deadline miss in every
#: scene (docs/driver_contract.md, "Pre-roll"). Section 0 has no deadline.
PRE_ROLL = 1


def sim_values(rig: Rig, clock_drift: float = 0.0) -> dict:
    """The simulator's parameters of ``rig`` (:meth:`Rig.dimensionless`): physical speed
    is time_scale = omega_n, here omega_n / (1 + clock_drift) so that the simulated rig
    clock drifts by ``clock_drift`` against ROS time (:class:`SimulatedClock`).
    ParameterError (one line naming the rig field) for what the simulator does not
    model: a velocity noise other than the position noise, an actuator latency. The stop
    (the rig file's ``stop`` section) is sim_node's contact parameters
    (Rig.contact_values; the rigid wall's with sim_node's defaults for the rest): a
    compliant stop runs in the rig scene as the wall does, realtime with the correction
    as a force pulse (docs/theory_contact.md §16)."""
    d = rig.dimensionless()
    if d["sensor_velocity"] and d["sensor_velocity_noise"] != d["sensor_noise"]:
        raise ParameterError(
            f"sensor.velocity_noise={rig.sensor.velocity_noise!r} m/s is not simulated: "
            "sim_node's sensor draws one noise std for x~ and v~; valid is "
            f"{d['sensor_noise'] * rig.scales.velocity!r} m/s (= noise / l * omega_n l), or "
            "measures: position")
    if rig.actuator.latency != 0.0:
        raise ParameterError(f"actuator.latency={rig.actuator.latency!r} s is not simulated: "
                             "valid in a simulated rig is 0 s")
    common = {"state_period": d["state_period"],
              "sensor_noise": d["sensor_noise"], "sensor_quantum": d["sensor_quantum"],
              "sensor_velocity": bool(d["sensor_velocity"]), "pulse_width": d["pulse_width"],
              "force_limit": d["force_limit"], "actuator_bandwidth": d["actuator_bandwidth"],
              "actuation_delay": d["actuation_delay"],
              "time_scale": rig.omega_n / (1.0 + clock_drift), "pre_roll": PRE_ROLL}
    if rig.n > 1:        # the n-DOF scene of Rig.model(): the model gives the rest
        if rig.stop.type != "rigid":
            raise ParameterError(f"stop.type={rig.stop.type!r} is not simulated for a rig of "
                                 f"{rig.n} masses: valid there is rigid (the n-DOF plant's "
                                 "stop is the rigid wall)")
        return {"delta_d": rig.model().delta_d, **common}
    p = rig.params()
    return {"zeta": p.zeta, "r": p.r, "omega": p.omega, "delta_d": p.delta_d, "tau0": 0.0,
            "pi2_offset": p.pi2_offset, **common,
            **{k: default_values()[k] for k in CONTACT_KEYS}, **rig.contact_values()}


def check_rig_values(rig_file: str, rig_values: dict, values: dict, free=()) -> None:
    """The parameters a rig file sets (``rig_values``) must not be given otherwise
    (``values``: what the node declared): ParameterError naming the first that differs,
    ``free`` excepted."""
    for key, value in rig_values.items():
        if key not in free and key in values and values[key] != value and not (
                isinstance(value, float) and math.isnan(value) and math.isnan(values[key])):
            raise ParameterError(f"{key}={values[key]!r} is invalid with rig_file={rig_file}: "
                                 f"valid is the rig's {value!r} (docs/rig.md; change the "
                                 "rig file, not the parameter)")


#: The controller's parameters that a rig file sets (:func:`controller_values`).
CONTROLLER_KEYS = ("zeta", "r", "omega", "pi2_offset", "delta_d", "actuation_delay", "c1",
                   "c2", "x_ref", "v_ref", "pi2_source", "answer_after_section",
                   "answer_lead", "sensor_noise", "state_period", "pulse_width", "force_limit",
                   "actuator_bandwidth")


def controller_values(rig: Rig, c2: float, mu: float = math.nan) -> dict:
    """The controller's parameters of ``rig``: its model, sensor and actuator (the pulse,
    its force limit and bandwidth, which the estimator integrates) in the model's units,
    the stream estimator answering each section with its last sample (the simulated rig
    keeps an answer that comes before its section), and the design for the budget's
    delay: c1 from the degenerate condition (Eq. 38 / (D5)) for ``c2``, or with ``c2``
    NaN for the c2 of least noise gain (dynamics.design.tuning.optimize_noise). A rig of
    n >= 2 masses: :func:`masses_controller_values` at ``mu`` (``c2`` must be NaN)."""
    # from its own module: dynamics.design.gains imports the orbit solver and with it
    # scipy.optimize, ~0.25 s of a rig controller's start that the design never used
    from grazing_control.dynamics.design.degenerate import degenerate_c1

    if rig.n > 1:
        if not math.isnan(c2):
            raise ParameterError(f"rig_c2={c2!r} is invalid for a rig of {rig.n} masses: "
                                 "valid is NaN (its n-DOF design's free parameter is rig_mu)")
        return masses_controller_values(rig, mu)
    if not math.isnan(mu):
        raise ParameterError(f"rig_mu={mu!r} is invalid for a rig of one mass: valid is NaN "
                             "(its design's free parameter is rig_c2)")
    p, d = rig.params(), rig.dimensionless()
    delay = d["actuation_delay"]
    if math.isnan(c2):
        from grazing_control.dynamics.design.tuning import optimize_noise

        c2 = optimize_noise(p, delay).c2
    return {"zeta": p.zeta, "r": p.r, "omega": p.omega, "pi2_offset": p.pi2_offset,
            "delta_d": p.delta_d, "actuation_delay": delay, "c1": degenerate_c1(p, c2, delay),
            "c2": float(c2), "x_ref": math.nan, "v_ref": math.nan, "pi2_source": "stream",
            "answer_after_section": False, "answer_lead": answer_lead(rig),
            "sensor_noise": d["sensor_noise"], "state_period": d["state_period"],
            "pulse_width": d["pulse_width"], "force_limit": d["force_limit"],
            "actuator_bandwidth": d["actuator_bandwidth"]}


#: The controller's parameters that a rig file of n >= 2 masses sets
#: (:func:`masses_controller_values`).
MASSES_CONTROLLER_KEYS = ("omega", "pi2_offset", "delta_d", "actuation_delay", "gains", "n",
                          "i_a", "mu", "sensor_coordinate", "pi2_source",
                          "answer_after_section", "answer_lead", "sensor_noise",
                          "state_period", "pulse_width", "force_limit", "actuator_bandwidth")


def masses_controller_values(rig: Rig, mu: float) -> dict:
    """The controller's parameters of a rig of n >= 2 masses: the n-DOF model controller
    (controller_values.model_controller_from_values) on :meth:`Rig.model`, its stream
    estimator reading the first measured mass (``sensor.masses[0]``: the impacting mass
    where the sensor sees it; the others are published on rig/sensor and not read), and
    the gains of the n-DOF pulse design for the budget's delay and the pulse's width
    (grazing design --rig FILE, dynamics.design.family.pulse_design) at ``mu``, or
    with ``mu`` NaN at its default (family.default_mu of the admissible set)."""
    from grazing_control.dynamics.design import family as nd

    model, d = rig.model(), rig.dimensionless()
    delay = nd.design_actuation(d["actuation_delay"], d["pulse_width"],
                                d["actuator_bandwidth"], d["actuator_latency"])
    if math.isnan(mu):
        mu = nd.default_mu([(float(lo), float(hi))
                            for lo, hi in nd.admissible_mu(model, "combined", delay)])[0]
    gains = [float(k) for k in nd.evaluate_design(model, mu, delay).gains]
    return {"omega": model.omega, "pi2_offset": model.pi2_offset, "delta_d": model.delta_d,
            "actuation_delay": d["actuation_delay"], "gains": gains, "n": model.n,
            "i_a": model.i_a, "mu": float(mu), "sensor_coordinate": int(rig.measured[0]),
            "pi2_source": "stream", "answer_after_section": False,
            "answer_lead": answer_lead(rig), "sensor_noise": d["sensor_noise"],
            "state_period": d["state_period"], "pulse_width": d["pulse_width"],
            "force_limit": d["force_limit"], "actuator_bandwidth": d["actuator_bandwidth"]}


def answer_lead(rig: Rig) -> float:
    """How long (model time) before a section's last sample the controller answers it:
    the time from the section to its pulse's start, budget - w/2 (4 ms of the acceptance
    rig's 5 ms budget, 2 ms pulse), so that the controller has that long, and the sensor's
    latency, to answer before the pulse must start; the samples of that stretch (9 of 150)
    are not used. Measured at physical speed on the loaded 2-core machine (900 periods,
    docs/benchmarks.md): answering with the last sample every deadline was missed
    (answer p50 6.3 ms after the section's sample went out), with 2 ms 594, with 4 ms 153;
    the spread stayed within 1.1x of the prediction."""
    return (rig.budget - rig.actuator.pulse_width / 2.0) * rig.omega_n


def first_section(rig: Rig, t: float) -> float:
    """The rig time of the first Pi2 section at or after rig time ``t``: where the
    forcing phase Omega t + phi equals tau2 (mod 2 pi)."""
    tau2 = rig.section_phase()
    phase = TWO_PI * rig.frequency * t + rig.phase
    return t + ((tau2 - phase) % TWO_PI) / (TWO_PI * rig.frequency)


class SimulatedClock:
    """The simulated rig's clock (module docstring): rig time = ``start`` + t / omega_n
    at model time t, ``start`` the first section at or after ``clock_start``."""

    def __init__(self, rig: Rig, clock_start: float, time_scale: float):
        self.rig = rig
        self.start = first_section(rig, clock_start)
        self.drift = rig.omega_n / time_scale - 1.0   # ROS s per rig s, less 1
        self.offset = math.nan                        # known once the scene has started

    def rig_time(self, t: float) -> float:
        """Rig-clock seconds of model time t."""
        return self.start + t / self.rig.omega_n

    def model_time(self, s: float) -> float:
        """Model time of rig-clock seconds s."""
        return (s - self.start) * self.rig.omega_n

    def started(self, ros_now: float, model_now: float) -> None:
        """The relation ROS = offset + (1 + drift) rig, from one reading of both clocks."""
        self.offset = ros_now - (1.0 + self.drift) * self.rig_time(model_now)

    def phase(self, s: float) -> float:
        """The forcing phase (rad, in [0, 2 pi)) at rig time s."""
        return (TWO_PI * self.rig.frequency * s + self.rig.phase) % TWO_PI


class DelayLine:
    """Items held until their time + ``latency`` (the sensor's latency, model time)."""

    def __init__(self, latency: float):
        self.latency = float(latency)
        self.items = deque()

    def push(self, t: float, item) -> None:
        self.items.append((t + self.latency, item))

    def due(self, now: float) -> list:
        """The items whose time + latency <= ``now``, oldest first."""
        out = []
        while self.items and self.items[0][0] <= now:
            out.append(self.items.popleft()[1])
        return out

    def next_time(self) -> float:
        """When the oldest item is due (inf: none held)."""
        return self.items[0][0] if self.items else math.inf


class Pacer:
    """Due about once per ``period`` of wall time on average, never twice within half a
    period: the rig/clock pairs, asked from every wake-up of the loop and from a timer
    (whichever runs first under load) without bursts after a stall.

    Due at ``wall`` once ``wall >= next``; :meth:`done` then moves ``next`` to
    ``max(next + period, wall + period / 2)``: on the period's grid while the callers
    keep up, half a period after a late pair otherwise. A pair that could not be taken
    (:meth:`done` not called) stays due.
    """

    def __init__(self, period: float):
        self.period = float(period)
        self.next = -math.inf

    def due(self, wall: float) -> bool:
        return wall >= self.next

    def done(self, wall: float) -> None:
        self.next = max(self.next + self.period, wall + 0.5 * self.period)


def force_of(rig: Rig, dv: float) -> float:
    """The pulse's force (N) of a correction Delta v~ of the actuated mass:
    F = m_a omega_n l Delta v~ / w (an impulse m_a Delta v spread over the width w;
    m_a = 1 / (M^-1)_aa, Rig.effective_mass: an impulse J on mass a changes v_a by
    (M^-1)_aa J; m for one mass)."""
    return rig.effective_mass * rig.scales.velocity * dv / rig.actuator.pulse_width


def correction_of(rig: Rig, force: float, width: float) -> float:
    """The correction Delta v~ of a pulse of ``force`` N over ``width`` s:
    Delta v~ = F w / (m_a omega_n l)."""
    return force * width / (rig.effective_mass * rig.scales.velocity)


def joint_names(rig: Rig) -> list:
    """``rig/sensor``'s ``name`` (docs/driver_contract.md): ``["mass"]`` for one mass,
    ``mass<i>`` of each measured mass (the rig file's ``sensor.masses`` order) for n."""
    return ["mass"] if rig.n == 1 else [f"mass{i}" for i in rig.measured]


def sensor_positions(rig: Rig, x) -> list:
    """The measured masses' positions (m) of the model's positions x~ (all n
    coordinates): x_i = l x~_i, in :func:`joint_names`' order."""
    length = rig.scales.length
    return [float(x[i]) * length for i in rig.measured]


def model_positions(rig: Rig, names, positions) -> dict:
    """The model coordinates {i: x~_i} of a ``rig/sensor`` message's ``names`` and
    ``positions`` (m): x~_i = x_i / l. ValueError (one line) for a name that is not a
    measured mass of this rig or a count that differs."""
    want = joint_names(rig)
    if list(names) != want or len(positions) != len(want):
        raise ValueError(f"rig/sensor names {list(names)!r} with {len(positions)} positions: "
                         f"valid is {want!r} with one position each")
    length = rig.scales.length
    return {i: float(x) / length for i, x in zip(rig.measured, positions)}


class Sections:
    """The controller's sections in the rig clock (docs/driver_contract.md, "Sections").

    The first ``rig/phase`` reference fixes the origin: the first section at or after
    its stamp is the model's t = 0 (the simulated rig publishes a reference at each
    section, its first at its own t = 0, so both count sections alike); later references
    are checked against it (:meth:`check`). Model time tau = omega_n (s - origin).
    """

    #: A reference whose phase differs from the origin's sections by more than this
    #: (rad) is a mismatch (counted).
    PHASE_TOLERANCE = 1e-6

    def __init__(self, rig: Rig):
        self.rig = rig
        self.tau2 = rig.section_phase()
        self.origin = None

    def reference(self, t_ref: float, frequency: float, phase: float) -> bool:
        """A ``rig/phase`` reference; False when it disagrees with the origin's sections
        (another frequency, or a phase off by more than PHASE_TOLERANCE)."""
        if not (math.isfinite(t_ref) and math.isfinite(frequency) and frequency > 0.0
                and math.isfinite(phase)):
            return False
        if self.origin is None:
            ahead = (self.tau2 - phase) % TWO_PI
            if ahead > TWO_PI - self.PHASE_TOLERANCE:     # the reference is on a section
                ahead = 0.0
            self.origin = t_ref + ahead / (TWO_PI * frequency)
        if abs(frequency - self.rig.frequency) > 1e-9 * self.rig.frequency:
            return False
        want = self.tau2 + TWO_PI * self.rig.frequency * (t_ref - self.origin)
        err = abs(math.remainder(phase - want, TWO_PI))
        return err <= self.PHASE_TOLERANCE

    def model_time(self, s: float) -> float:
        return (s - self.origin) * self.rig.omega_n

    def rig_time(self, t: float) -> float:
        return self.origin + t / self.rig.omega_n

    def apply_time(self, t_k: float) -> float:
        """The rig time at which section k's pulse starts: t_k + budget - w / 2."""
        return t_k + self.rig.budget - self.rig.actuator.pulse_width / 2.0
