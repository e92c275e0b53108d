"""The controller's re-identification in the loop (issue 29 section 3), without ROS.

The node side of :mod:`grazing_control.dynamics.estimation.reidentification`: its parameters, the
trigger rule, and the record of each decision. In stream mode with ``estimator`` model
the controller keeps the last ``reidentify_periods`` periods of the stream it received
(samples, the phase reference, the kicks that acted, the impacts known); a refit is
requested by the std_srvs/Trigger service ``~/reidentify``, or, with ``reidentify``
true, when the consistency test's verdict is a mismatch (``consistency_window`` >= 1).
The fit runs in a worker thread; its result is applied at the next Pi2 section (after
that section's estimate, before its correction): the estimator moves to the new model
and Eq. 28 to the new gains and X**, or nothing changes when the plan is a refusal.

Parameters:

``reidentify``          refit when the consistency test fails (needs consistency_window >= 1);
``reidentify_periods``  the refit's window in periods (integer >= MIN_PERIODS);
``design_conditions``   the design's conditions re-checked for the new model (combined,
                        impacting, non-impacting: ``grazing design``'s sets).

A model-file controller (n masses, issue 32) runs the same path: the record holds its
sensor coordinate's stream (which must be the wall coordinate i_w for a refit) and each
section's 2n-state estimate; the refit is the modal fit realised as a model file, the
redesign the family's k(mu) at the running mu, delay and pulse
(:class:`~grazing_control.dynamics.estimation.reidentification.VectorGains`); the switch
moves the estimator, the law's gains and X**, and the controller's model
(:class:`~grazing_control.ros.controller_values.ModelController`: the prediction of a
late answer) to the new model. Its row has zeta the lowest mode's damping ratio, c1 and
c2 NaN (the gains are logged), x_ref and v_ref the wall coordinate's X**.

Each decision (a switch, or a refusal with its reason) is one row on
``controller/model_switch`` (sensor_msgs/JointState, stamp t_k of the section it was
decided at, ``name`` = :data:`SWITCH_FIELDS`, ``position`` = the values, NaN where there is
none), and the latest on /diagnostics.
"""

from __future__ import annotations

import math

import numpy as np

from grazing_control.dynamics.estimation.reidentification import (CONDITIONS, MIN_PERIODS, REASONS,
                                                       REFIT_PERIODS,
                                                       ReidentificationError, Reidentifier,
                                                       StreamRecord, VectorGains,
                                                       switch_estimator)
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import ParameterError

__all__ = ["REID_DEFAULTS", "REID_KEYS", "SWITCH_TOPIC", "SWITCH_FIELDS", "reid_from_values",
           "switch_row", "describe_plan", "AutoTrigger", "declare_reidentify", "ReidentifySide"]

#: The topic of the decisions (recorded by default).
SWITCH_TOPIC = "controller/model_switch"
#: The parameters with their defaults (off).
REID_DEFAULTS = {"reidentify": False, "reidentify_periods": REFIT_PERIODS,
                 "design_conditions": "combined"}
REID_KEYS = tuple(REID_DEFAULTS)
#: The names of a decision row's values, in order: ``switched`` 1 (0: refused),
#: ``reason`` 0 (switched) or 1 + the index of dynamics.estimation.reidentification.REASONS,
#: ``requested_at`` the section of the request, then the new model with standard
#: errors, its gains and X**, and the fit's numbers.
SWITCH_FIELDS = ("switched", "reason", "requested_at", "zeta", "zeta_se", "r", "r_se",
                 "delta_d", "delta_d_se", "c1", "c2", "x_ref", "v_ref", "periods", "impacts",
                 "sigma", "phase_error", "cpu_s")


def reid_from_values(values: dict, period: float):
    """(StreamRecord, Reidentifier, auto) for the controller's parameters, or None when
    the stream mode with the model estimator is off (then ``reidentify`` must be false);
    ParameterError naming the parameter and its valid range."""
    periods = values["reidentify_periods"]
    if isinstance(periods, bool) or int(periods) != periods or periods < MIN_PERIODS:
        raise ParameterError(f"reidentify_periods={periods!r} is invalid: valid range is an "
                             f"integer >= {MIN_PERIODS} periods")
    conditions = values["design_conditions"]
    if conditions not in CONDITIONS:
        raise ParameterError(f"design_conditions={conditions!r} is invalid: valid values are "
                             f"{', '.join(CONDITIONS)}")
    auto = bool(values["reidentify"])
    if (values["pi2_source"] != "stream" or values["estimator"] != "model"
            or not math.isfinite(period)):
        if auto:
            raise ParameterError(f"reidentify=True is invalid with pi2_source="
                                 f"{values['pi2_source']} estimator={values['estimator']}: "
                                 "valid only with pi2_source=stream and estimator=model")
        return None
    if auto and not int(values["consistency_window"]) >= 1:
        raise ParameterError("reidentify=True is invalid with consistency_window=0: valid "
                             "only with a consistency test (consistency_window >= 1)")
    return (StreamRecord(period, int(periods)),
            Reidentifier(conditions, sigma=float(values["sensor_noise"])), auto)


class AutoTrigger:
    """When a mismatch verdict requests a refit: on the first mismatch section once the
    record holds a whole window, and again only once ``holdoff`` periods have passed
    since the last decision (a fresh window of data), never while one runs. After a
    switch the monitor restarts (its window held the old model's innovations)."""

    def __init__(self, holdoff: int):
        self.holdoff = int(holdoff)
        self.last = None

    def wants(self, k: int, mismatch: bool) -> bool:
        return mismatch and (self.last is None or k - self.last >= self.holdoff)

    def decided(self, k: int) -> None:
        self.last = k


def switch_row(plan=None, error: ReidentificationError | None = None, law=None,
               requested_at=None) -> list:
    """The values of :data:`SWITCH_FIELDS` for a SwitchPlan (or a refusal before any
    fit: ``error`` alone); ``law`` the control law after the decision (its gains and
    X**)."""
    nan = math.nan
    err = error if error is not None else (plan.error if plan is not None else None)
    fit = plan.refit if plan is not None else None
    req = plan.requested_at if plan is not None else requested_at
    row = [0.0 if err is not None else 1.0,
           0.0 if err is None else 1.0 + REASONS.index(err.reason),
           nan if req is None else float(req)]
    vector = plan is not None and isinstance(plan.gains, VectorGains)
    if fit is not None:
        m, se = fit.model, fit.stderr
        zeta = fit.modal.damping_ratio[0] if fit.modal is not None else m.zeta
        row += [zeta, se["zeta"], m.r, se["r"], m.delta_d, se["delta_d"]]
    else:
        row += [nan] * 6
    if err is None and plan is not None and not vector:
        row += [plan.gains.c1, plan.gains.c2]
    else:
        row += [nan, nan]
    if law is not None and err is None and vector:     # the wall coordinate's X**
        row += [law.x_ref[fit.model.i_w], law.v_ref[fit.model.i_w]]
    else:
        row += [law.x_ref, law.v_ref] if (law is not None and err is None) else [nan, nan]
    if fit is not None:
        row += [fit.periods, fit.impacts, fit.sigma, fit.phase_error, fit.cpu_s]
    else:
        row += [nan] * 5
    return [float(x) for x in row]


def describe_plan(plan=None, error: ReidentificationError | None = None, k=None) -> str:
    """One line: the switch (new model with standard errors, new gains) or the refusal
    (its reason and message)."""
    err = error if error is not None else plan.error
    at = "" if k is None else f" at section {k}"
    if err is not None:
        return f"re-identification refused{at} ({err.reason}): {err}; model and gains kept"
    m, se, g = plan.refit.model, plan.refit.stderr, plan.gains
    if isinstance(g, VectorGains):
        f = plan.refit.modal
        modes = ", ".join(f"Omega={o:.6g} zeta={z:.6g}" for o, z in
                          zip(f.natural_frequency, f.damping_ratio))
        return (f"model switched{at}: {modes}, r={m.r:.6g} ({se['r']:.2g}), delta_d="
                f"{m.delta_d:.6g} ({se['delta_d']:.2g}); k={[round(x, 9) for x in g.k]} "
                f"(mu={g.mu:.6g}; fit of {plan.refit.periods:.0f} periods, "
                f"{plan.refit.impacts} impacts, {plan.refit.cpu_s:.1f} s CPU)")
    return (f"model switched{at}: zeta={m.zeta:.6g} ({se['zeta']:.2g}), r={m.r:.6g} "
            f"({se['r']:.2g}), delta_d={m.delta_d:.6g} ({se['delta_d']:.2g}); c1={g.c1:.6g} "
            f"c2={g.c2:.6g} (fit of {plan.refit.periods:.0f} periods, {plan.refit.impacts} "
            f"impacts, {plan.refit.cpu_s:.1f} s CPU)")


def declare_reidentify(declare) -> None:
    """Declare the parameters (:data:`REID_DEFAULTS`) with ``declare(name, default,
    descriptor)`` (the controller's ``d``)."""
    from .common import bool_descriptor, int_descriptor, string_descriptor

    declare("reidentify", False, bool_descriptor(
        "stream mode, estimator model: refit the model on the last reidentify_periods "
        "periods when the consistency test fails, and switch to it at a Pi2 section where "
        "its design is admissible (issue 29; also on demand: ~/reidentify)", True,
        constraints="true only with pi2_source stream, estimator model and "
                    "consistency_window >= 1"))
    declare("reidentify_periods", REFIT_PERIODS, int_descriptor(
        f"the refit's window in periods, >= {MIN_PERIODS}", MIN_PERIODS, read_only=True))
    declare("design_conditions", "combined", string_descriptor(
        "the design conditions re-checked for a refitted model before the switch "
        "(grazing design's sets)", True, CONDITIONS))


class ReidentifySide:
    """The controller's side of the re-identification: feeds the StreamRecord, asks the
    worker, applies a finished plan at a Pi2 section, publishes and logs each decision
    (module docstring). ``node`` is the ControllerNode (its stream, model, law, monitor,
    logger, pub_switch)."""

    def __init__(self, node, record: StreamRecord, worker: Reidentifier, auto: bool):
        self.node, self.record, self.worker, self.auto = node, record, worker, auto
        self.trigger = AutoTrigger(record.periods)
        self.switches = 0
        self.refused = {}               # reason -> count
        self.last = None                # the latest decision's line
        self._diag_refused = 0
        self._state = None              # this section's (x^, v^, by the model filter)
        self.omega = node.model.omega

    @classmethod
    def from_node(cls, node, values: dict):
        """The side of a controller node, None outside the stream's model filter (its
        parameters validated in every mode: ParameterError)."""
        made = reid_from_values(values, math.nan if node.model is None else node.model.period)
        return None if made is None or node.stream is None else cls(node, *made)

    # ---------------------------------------------------------------- the stream
    def sample(self, t: float, x: float, v: float) -> None:
        """A stream sample, less the augmented filter's bias estimate where it estimates
        one (the fit's model has no sensor offset), with the phase reference omega t
        (the fit's forcing phase theta takes the offset)."""
        self.samples((t,), (x,), (v,))

    def samples(self, t, x, v) -> None:
        """A run of stream samples in increasing time, as :meth:`sample` on each (no
        section falls due among them: the bias estimate is the same for all)."""
        b = self.node.stream.bias if getattr(self.node.stream, "use_bias", False) else None
        w, cos, sin = self.omega, math.cos, math.sin
        self.record.add_samples([(ti, xi if b is None else xi - b, vi, cos(w * ti),
                                  sin(w * ti)) for ti, xi, vi in zip(t, x, v)])

    def answered(self, k: int, dv: float) -> None:
        if self._state is not None:
            self.record.add_section(k, self._state[0], dv,
                                    k * self.node.model.period + self.node.actuation_delay,
                                    self._state[1])

    def acted(self, k: int, dv: float) -> None:
        self.record.acted(k, dv, k * self.node.model.period + self.node.actuation_delay)

    # ---------------------------------------------------------------- decisions
    def at_section(self, k: int, key: tuple, est) -> None:
        """Section k's estimate is made, its answer not yet: apply a finished plan here,
        or start a refit on a mismatch verdict (``reidentify``)."""
        p, ndof = self.node.model, getattr(self.node, "ndof", None)
        self._state = ((p.x_ref + est.z[0], p.v_ref + est.z[1]) if ndof is None else
                       tuple(np.concatenate([ndof.x_ref, ndof.v_ref]) + np.asarray(est.z)),
                       est.source == "model")
        plan = self.worker.take()
        if plan is not None:
            self._apply(plan, k, key)
            return
        v = self.node.verdict
        if (self.auto and v is not None and v.k == k and v.status == "mismatch"
                and not self.worker.running and self.trigger.wants(k, True)
                and self.record.covered >= self.record.periods - 0.5):
            ok, _line = self.request(k)
            if not ok:
                self.trigger.decided(k)     # e.g. too_few_periods since a restart

    def request(self, k: int | None = None) -> tuple:
        """Start a refit now: (True, what started) or (False, the refusal's line; a
        refusal row published)."""
        n = self.node
        if k is None:
            k = n.stream.next_k - 1 if n.stream.next_k is not None else None
        try:
            gains = self._gains()
            self.worker.request(self.record, n.model, gains, k)
        except ReidentificationError as exc:
            from .cdr import stamp_parts

            self._refused(exc, k, None if k is None else stamp_parts(k * n.model.period))
            return False, describe_plan(error=exc, k=k)
        line = (f"re-identification started at section {k}: a refit of the last "
                f"{self.record.covered:.1f} periods")
        n.get_logger().info(line)
        return True, line

    def _gains(self):
        """The running gains as the worker takes them: Gains(c1, c2, delay), or an
        n-DOF law's VectorGains (k, the delay or the design's Actuation of the pulse,
        mu); ReidentificationError ``not_identified`` where the stream is not the wall
        coordinate's (the modal fit's data)."""
        n = self.node
        if getattr(n, "ndof", None) is None:
            return Gains(n.law.gains.c1, n.law.gains.c2, n.actuation_delay)
        model = n.ndof.model
        if n.stream.coordinate != model.i_w:
            raise ReidentificationError(
                "not_identified", f"the stream is coordinate {n.stream.coordinate}'s, not "
                f"the wall coordinate i_w={model.i_w}'s: the n-DOF refit fits x_w "
                "(sensor_coordinate must be i_w)")
        width, _limit, act = (tuple(n.pulse) + (None,))[:3]
        actuation = n.actuation_delay
        if width > 0.0:
            from grazing_control.dynamics.design.family import Actuation

            actuation = Actuation(n.actuation_delay, width, 0.0 if act is None else
                                  act.time_constant, 0.0 if act is None else act.latency)
        return VectorGains.of(model, n.ndof.gains, actuation)

    def _refused(self, error, k, key, plan=None) -> None:
        self.refused[error.reason] = self.refused.get(error.reason, 0) + 1
        self.last = describe_plan(plan, error if plan is None else None, k)
        self.node.get_logger().warning(self.last)
        self._publish(switch_row(plan, error if plan is None else None,
                                 requested_at=k), key)

    def _apply(self, plan, k: int, key: tuple) -> None:
        """The switch at section k (docs/theory_reidentification.md, "The switch"), or
        the refusal: the old model, estimator and gains kept."""
        self.trigger.decided(k)
        if plan.error is not None:
            self._refused(plan.error, k, key, plan)
            return
        n = self.node
        new = plan.refit.model
        switch_estimator(n.stream, new, plan.refit.stderr["delta_d"])
        n.model = new
        law = n.law
        if getattr(n, "ndof", None) is None:
            law.configure(Gains(plan.gains.c1, plan.gains.c2), new.x_ref, new.v_ref,
                          law.enable_after, law.saturation)
        else:                           # the n-DOF controller's model, X** and k
            import dataclasses

            from grazing_control.oscillator.ndof.section import NdofSection

            section = NdofSection(new)
            X = np.asarray(section.flow.particular(section.tau2), dtype=float)
            n.ndof = dataclasses.replace(n.ndof, model=new, section=section,
                                         gains=plan.gains.k, x_ref=X[:new.n].copy(),
                                         v_ref=X[new.n:].copy())
            law.configure(plan.gains.k, n.ndof.x_ref, n.ndof.v_ref, law.enable_after,
                          law.saturation)
        if n.monitor is not None:       # its window held the old model's innovations
            n.monitor.reset()
            n.verdict = None
        self.switches += 1
        self.last = describe_plan(plan, k=k)
        n.get_logger().warning(self.last)
        self._publish(switch_row(plan, law=law), key)

    def _publish(self, row, key) -> None:
        from sensor_msgs.msg import JointState

        msg = JointState(name=list(SWITCH_FIELDS), position=row)
        if key is not None:
            msg.header.stamp.sec, msg.header.stamp.nanosec = key
        self.node.pub_switch.publish(msg)

    # ---------------------------------------------------------------- reports
    def diagnose(self, stat) -> None:
        """/diagnostics: switches, refusals by reason, whether a fit runs, the latest
        decision; WARN when a refusal came since the last message."""
        from .diagnostics import WARN

        stat.add("model switches", self.switches)
        stat.add("refits refused", ", ".join(f"{r} {c}" for r, c in self.refused.items())
                 or "0")
        stat.add("refit running", str(self.worker.running).lower())
        if self.last is not None:
            stat.add("re-identification", self.last)
        total = sum(self.refused.values())
        if total > self._diag_refused:
            stat.merge_summary(WARN, f"{total - self._diag_refused} re-identifications "
                                     "refused since the last message (model and gains kept)")
        self._diag_refused = total

    def summary(self) -> str:
        return (f" model_switches={self.switches} refits_refused="
                f"{sum(self.refused.values())}")
