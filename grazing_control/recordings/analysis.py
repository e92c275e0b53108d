"""Offline analysis of a control scene: numbers and figures from a recording alone.

A scene is what the nodes publish: the Pi2 samples (before correction), the
corrections that answered them, and the impacts. :class:`Scene` holds those arrays;
:func:`scene_from_bag` reads them from a recording (topics ``/oscillator/pi2``,
``/controller/velocity_correction``, ``/oscillator/impact``), and
:func:`scene_from_simulation` from a :class:`grazing_control.dynamics.simulation.simulate.SimulationResult`,
so the same numbers can be compared between the node run and the core.

Numbers (:func:`summarize`):

* ``control_on``: the first sample answered with a non-zero correction;
* ``uncontrolled_period``: the smallest p <= 64 with the last ``window`` samples before
  control p-periodic to a tolerance, or None (not periodic: chaotic or transient);
* ``samples_to_converge``: samples after ``control_on`` until every later sample stays
  within ``tol`` of the final one;
* ``final_pi2`` and ``final_impacts_per_period`` (1 for a 1/1 motion).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

__all__ = ["Scene", "scene_from_bag", "scene_from_simulation", "summarize", "plot_scene",
           "fmt", "complex_text", "control_lines"]

TOPIC_PI2 = "/oscillator/pi2"
TOPIC_CORRECTION = "/controller/velocity_correction"
TOPIC_IMPACT = "/oscillator/impact"


@dataclass
class Scene:
    """Arrays of one run: sample times, Pi2 states, corrections, impacts.

    Attributes
    ----------
    t : (N,) sample times; pi2 : (N, 2) states (x, v) before correction;
    correction : (N,) correction answering each sample (0 when none arrived);
    impacts : (M, 4) [time, v-, v+, phase].
    """

    t: np.ndarray
    pi2: np.ndarray
    correction: np.ndarray
    impacts: np.ndarray

    @property
    def impacts_per_period(self) -> np.ndarray:
        """Impacts between consecutive samples (the last period is open-ended)."""
        edges = np.append(self.t, np.inf)
        counts, _ = np.histogram(self.impacts[:, 0], bins=edges) if len(self.t) else (np.zeros(0), None)
        return counts.astype(int)


def _key(header):
    return header.stamp.sec, header.stamp.nanosec


def scene_from_bag(bag_dir) -> Scene:
    """Read a scene from a recording (see :mod:`grazing_control.ros.recording`).

    Corrections are matched to samples by their header stamp (the stamp of the
    sample they answer, spec ros.md); a sample without an answer gets 0.
    """
    from grazing_control.ros.recording import read_messages

    samples, corrections, impacts = [], {}, []
    try:
        for m in read_messages(bag_dir, topics=[TOPIC_PI2, TOPIC_CORRECTION, TOPIC_IMPACT]):
            msg = m.message
            if m.topic == TOPIC_PI2:
                if len(msg.position) and len(msg.velocity):     # else: not a sample, skipped
                    samples.append((_key(msg.header), msg.position[0], msg.velocity[0]))
            elif m.topic == TOPIC_CORRECTION:
                corrections[_key(msg.header)] = msg.twist.linear.x
            else:
                sec, nsec = _key(msg.header)
                impacts.append((sec + 1e-9 * nsec, msg.vector.x, msg.vector.y, msg.vector.z))
    except (OSError, ValueError):
        raise
    except Exception as exc:        # mcap's own errors, a schema that does not decode, ...
        raise ValueError(f"{bag_dir}: not a readable recording ({type(exc).__name__}: "
                         f"{str(exc).splitlines()[0] if str(exc) else ''})") from None
    if not samples:
        raise ValueError(f"{bag_dir}: no Pi2 samples on {TOPIC_PI2}: not a scene recording")
    samples.sort()
    impacts.sort()
    t = np.array([sec + 1e-9 * nsec for (sec, nsec), _x, _v in samples])
    corr = np.array([corrections.get(key, 0.0) for key, _x, _v in samples])
    return Scene(t, np.array([[x, v] for _k, x, v in samples]).reshape(-1, 2), corr,
                 np.array(impacts, dtype=float).reshape(-1, 4))


def scene_from_simulation(res) -> Scene:
    """The same arrays from a core simulation result."""
    n = len(res.pi2)
    t = np.arange(n) * res.params.period
    imp = res.impacts
    return Scene(t, res.pi2.copy(), res.corrections.copy(),
                 np.column_stack([imp[:, 1], imp[:, 3], imp[:, 4], imp[:, 2]]) if len(imp) else
                 np.zeros((0, 4)))


def _periodicity(x: np.ndarray, tol: float, max_period: int = 64):
    for p in range(1, max_period + 1):
        if len(x) <= p:
            return None
        if np.max(np.abs(x[p:] - x[:-p])) <= tol:
            return p
    return None


def summarize(scene: Scene, tol: float = 1e-8, window: int = 200) -> dict:
    """The scene's numbers (see the module docstring); JSON-serialisable."""
    n = len(scene.t)
    nonzero = np.flatnonzero(scene.correction != 0.0)
    on = int(nonzero[0]) if nonzero.size else None
    counts = scene.impacts_per_period
    before = scene.pi2[:on] if on is not None else scene.pi2
    period = _periodicity(before[-window:], tol) if len(before) >= 2 else None
    out = {
        "samples": n,
        "impacts": int(len(scene.impacts)),
        "control_on": on,
        "uncontrolled_period": period,
        "uncontrolled_impacts_per_period": _histogram(counts if on is None else counts[:on]),
        "samples_to_converge": None,
        "final_pi2": scene.pi2[-1].tolist() if n else None,
        "final_impacts_per_period": (int(counts[-2]) if n >= 2 else None),
        "final_v_minus": float(scene.impacts[-1, 1]) if len(scene.impacts) else None,
        "max_abs_correction": float(np.max(np.abs(scene.correction))) if n else 0.0,
    }
    if on is not None and n > on + 1:
        dist = np.max(np.abs(scene.pi2[on:] - scene.pi2[-1]), axis=1)
        outside = np.flatnonzero(dist > tol)
        conv = int(outside[-1] + 1) if outside.size else 0
        if conv < n - on - 1:
            out["samples_to_converge"] = conv
            tail = counts[on + conv:n - 1]
            out["final_impacts_per_period"] = int(np.round(np.mean(tail))) if tail.size else None
            out["one_impact_per_period_after_convergence"] = bool(tail.size and np.all(tail == 1))
    return out


def plot_scene(scene: Scene, title: str, path) -> None:
    """Four panels: Pi2 before/after control, Pi2 x per sample, impact velocities, corrections."""
    from grazing_control.support.plotting import pyplot, save_png

    plt = pyplot()

    summary = summarize(scene)
    on = summary["control_on"] if summary["control_on"] is not None else len(scene.t)
    k = np.arange(len(scene.t))
    fig, ax = plt.subplots(2, 2, figsize=(11, 8), constrained_layout=True)
    a = ax[0, 0]
    a.plot(scene.pi2[:on, 0], scene.pi2[:on, 1], ".", ms=2, color="tab:red", label="before control")
    a.plot(scene.pi2[on:, 0], scene.pi2[on:, 1], ".", ms=3, color="tab:blue", label="after control")
    a.plot(*scene.pi2[-1], "k*", ms=10, label="final sample")
    a.set(xlabel="x on Π2", ylabel="v on Π2", title="Π2 samples")
    a.legend(fontsize=8)
    a = ax[0, 1]
    a.plot(k, scene.pi2[:, 0], ".", ms=2)
    a.axvline(on, color="k", lw=0.8, ls="--", label="control on")
    a.set(xlabel="sample k", ylabel="x on Π2", title="Π2 position per forcing period")
    a.legend(fontsize=8)
    a = ax[1, 0]
    if len(scene.impacts):
        period = np.median(np.diff(scene.t)) if len(scene.t) > 1 else 1.0
        a.semilogy((scene.impacts[:, 0] - scene.t[0]) / period, scene.impacts[:, 1], ".", ms=2)
    a.axvline(on, color="k", lw=0.8, ls="--")
    a.set(xlabel="time / T", ylabel="impact velocity v⁻", title="impact velocities")
    a = ax[1, 1]
    a.plot(k, scene.correction, ".-", ms=2, lw=0.5)
    a.set(xlabel="sample k", ylabel="Δv", title="velocity corrections")
    fig.suptitle(title)
    save_png(fig, path, dpi=110)


def _histogram(counts):
    """Impacts per period 0, 1, 2, ... as counts of periods (None for no period)."""
    counts = np.asarray(counts, dtype=np.int64)
    return np.bincount(counts).tolist() if counts.size else None


# ------------------------------------------------- report lines of every model (any n)
def fmt(v, spec=".4g") -> str:
    """A number of a report: "—" for None, ``spec`` for a float, str otherwise."""
    if v is None:
        return "—"
    if isinstance(v, float):
        return format(v, spec)
    return str(v)


def complex_text(z) -> str:
    """A multiplier, (re, im) or complex, as "re" or "re+imi" (6 digits)."""
    z = complex(*z) if isinstance(z, (list, tuple)) else complex(z)
    return f"{z.real:.6g}" if z.imag == 0 else f"{z.real:.6g}{z.imag:+.6g}i"


def control_lines(numbers: dict) -> list:
    """The report's lines on the control of a scene, the same for the 1-DOF and the n-DOF
    scenes: the switch-on (sample, time) and the samples to converge; the contraction per
    sample after it, measured
    (:func:`grazing_control.recordings.numbers.measured_contraction`) against the
    predicted orbit's |lambda|max and multipliers; the prediction's notes. ``numbers``:
    the scene's numbers (keys ``control_on_sample``, ``control_on_time_s``,
    ``samples_to_converge``, ``measured_contraction``, ``predicted``,
    ``contraction_relative_error``)."""
    n = numbers
    if n["control_on_sample"] is None:
        lines = ["* control never switched on (no non-zero correction)"]
    else:
        lines = [f"* control on at sample {n['control_on_sample']} (t = "
                 f"{n['control_on_time_s']:.6g} s); converged to 1e-8 after "
                 f"{fmt(n['samples_to_converge'])} samples"]
    meas, pred, relative_error = (n["measured_contraction"], n["predicted"],
                                  n.get("contraction_relative_error"))
    if meas and meas.get("rho"):
        lines.append(f"* contraction per sample: measured ρ = {meas['rho']:.6f} (median ratio "
                     f"{meas['median_ratio']:.6f}, samples {meas['first']}–{meas['last']}); "
                     f"predicted |λ|max = {fmt(pred.get('rho'), '.6f')} "
                     f"(multipliers {', '.join(complex_text(z) for z in pred.get('multipliers', []))}); "
                     f"relative difference {fmt(relative_error, '.1e')}")
    elif meas:
        lines.append(f"* contraction: not measured ({meas.get('reason')})")
    for key in ("controlled_orbit_error", "uncontrolled_orbit_error", "note", "error"):
        if key in pred:
            lines.append(f"* prediction: {pred[key]}")
    return lines
