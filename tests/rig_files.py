"""Rig files for the tests: seeded random rigs in SI (valid by construction), the issue's
lab rig, and hostile mutations of a rig file (each with the field its refusal must name)."""

import copy
import math

import numpy as np
import yaml

from grazing_control.oscillator.params import OscillatorParams

#: config/rigs/lab_20hz.yaml as a mapping (the issue's acceptance rig).
LAB = {
    "mass": "0.5 kg", "natural_frequency": "20 Hz", "damping_ratio": 0.01, "restitution": 0.7,
    "gap": "11.408089687179837 mm",
    "forcing": {"type": "force", "amplitude": "50 N", "frequency": "13.342666649999167 Hz",
                "phase": "0 rad"},
    "sensor": {"measures": "position", "rate": "2 kHz", "noise": "2 um", "resolution": "0 m",
               "latency": "0.5 ms"},
    "actuator": {"pulse_width": "2 ms", "force_limit": "20 N", "latency": "0 s"},
    "controller": {"budget": "5 ms"},
}


def random_rig(rng, forcing=None, depth=None) -> dict:
    """A valid rig file's mapping with random SI values (module docstring); ``depth``:
    the stop at Delta d = -depth d* (default: Delta d from -1e-8 to -0.1)."""
    def U(a, b):
        return float(rng.uniform(a, b))

    def C(values):
        return values[int(rng.integers(len(values)))]

    forcing = forcing or ("force" if rng.random() < 0.5 else "base")
    m = 10 ** U(-2, 2)
    fn = 10 ** U(0, 3)
    zeta = U(0.001, 0.3)
    r = U(0.05, 0.95)
    omega = U(0.3, 2.5)
    pi2_offset = U(0.3, 3.0)
    f = omega * fn
    wn = 2 * math.pi * fn
    p = OscillatorParams(zeta=zeta, r=r, omega=omega, pi2_offset=pi2_offset)
    if forcing == "force":
        amp = 10 ** U(-2, 3)
        F0 = amp
        forcing_doc = {"type": "force", "amplitude": f"{amp!r} N"}
    else:
        amp = 10 ** U(-6, -2)
        F0 = m * (2 * math.pi * f) ** 2 * amp
        forcing_doc = {"type": "base", "amplitude": f"{amp!r} m", "stop": "frame"}
    length = F0 / (m * wn * wn)
    dd = -10 ** U(-8, -1) if depth is None else -depth * p.d_star
    gap = (p.d_star + dd) * length
    T = 1.0 / f
    limit = min(T, (p.period - pi2_offset / omega) / wn)
    width = U(0.0, 0.3) * limit
    budget = width / 2 + U(0.05, 0.95) * (limit - width)
    forcing_doc.update(frequency=f"{f!r} Hz", phase=f"{U(-math.pi, math.pi)!r} rad")
    doc = {"mass": f"{m!r} kg", "damping_ratio": zeta, "restitution": r, "gap": f"{gap!r} m",
           "forcing": forcing_doc,
           "sensor": {"rate": f"{U(20.5, 2000) * f!r} Hz",
                      "noise": f"{10 ** U(-9, -5)!r} m",
                      "resolution": f"{C([0.0, 1e-8])!r} m",
                      "latency": f"{U(0, 0.1) * T!r} s",
                      "measures": "position"},
           "actuator": {"pulse_width": f"{width!r} s",
                        "force_limit": f"{C([0.0, 10 ** U(-1, 3)])!r} N",
                        "latency": f"{U(0, 0.05) * T!r} s"},
           "controller": {"budget": f"{budget!r} s", "pi2_offset": f"{pi2_offset!r} rad"}}
    if rng.random() < 0.5:
        doc["natural_frequency"] = f"{fn!r} Hz"
    else:
        doc["stiffness"] = f"{m * wn * wn!r} N/m"
    if rng.random() < 0.3:
        doc["sensor"]["measures"] = "position_velocity"
        doc["sensor"]["velocity_noise"] = f"{10 ** U(-6, -2)!r} m/s"
    if rng.random() < 0.3:
        del doc["damping_ratio"]
        doc["damping"] = f"{2 * zeta * m * wn!r} N*s/m"
    return doc


def dump(doc) -> str:
    return yaml.dump(doc, Dumper=getattr(yaml, "CSafeDumper", yaml.SafeDumper), sort_keys=False,
                     allow_unicode=True)


def load(text):
    return yaml.load(text, Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))


# ---------------------------------------------------------------------- hostile files
#: field -> values that are not a valid value of it (each refusal names the field)
_BAD_QUANTITY = [None, 0.5, 7, True, "0.5", "abc", "1 parsec", "nan m", "inf kg", "-inf Hz",
                 "1e400 N", [], {}, ["1 m"], {"v": "1 m"}, "", "  ", "1e-300 m", "1e300 m"]
_FIELDS = {
    "mass": ["-0.5 kg", "0 kg", "5 m"],
    "natural_frequency": ["-20 Hz", "0 Hz", "20 s"],
    "gap": ["-1 mm", "0 m", "1 kg"],
    "forcing.amplitude": ["-50 N", "0 N", "5 m"],
    "forcing.frequency": ["-1 Hz", "0 Hz", "5 N"],
    "forcing.phase": ["1 m"],
    "sensor.rate": ["-2 kHz", "0 Hz", "5 s", "100 Hz", "1 GHz", "1e9 Hz"],
    "sensor.noise": ["-2 um", "2 Hz"],
    "sensor.resolution": ["-1 um", "1 s"],
    "sensor.latency": ["-1 ms", "1 m"],
    "actuator.pulse_width": ["-2 ms", "11 ms", "2 m", "70 ms"],
    "actuator.force_limit": ["-1 N", "2 m"],
    "actuator.latency": ["-1 ms", "2 m"],
    "actuator.force_constant": ["-1 N/A", "0 N/A", "1 N"],
    "controller.budget": ["-5 ms", "0 s", "80 ms", "1 s", "5 m", "60 ms"],
    "controller.pi2_offset": ["0 rad", "7 rad", "-1 rad", "1 m"],
}
_NUMBERS = {"damping_ratio": [0.0, 1.0, 1.5, -0.1, "0.01", "0.01 N", None, [0.01], math.nan,
                              math.inf, True],
            "restitution": [0.0, 1.0, 1.2, -0.5, "0.7", None, {}, math.nan, True]}


def _set(doc, field, value):
    head, _, tail = field.partition(".")
    if tail:
        doc[head][tail] = value
    else:
        doc[head] = value


def _delete(doc, field):
    head, _, tail = field.partition(".")
    if tail:
        del doc[head][tail]
    else:
        del doc[head]


def mutations(seed: int, count: int):
    """``count`` seeded (description, document or YAML text, field named) mutations of
    the lab rig: missing fields, bare numbers, wrong units, bad values, wrong types,
    unknown keys, a gap on the wrong side, a ground-fixed stop under base excitation,
    pulses and budgets out of range, too slow a sensor."""
    rng = np.random.default_rng(seed)
    kinds = ["bad", "missing", "unknown", "number", "type", "structure"]
    required = ["mass", "gap", "forcing.amplitude", "forcing.frequency", "sensor.rate",
                "sensor.noise", "sensor.latency", "actuator.pulse_width", "controller.budget",
                "restitution", "forcing", "sensor", "actuator", "controller"]
    out = []
    while len(out) < count:
        doc = copy.deepcopy(LAB)
        kind = kinds[int(rng.integers(len(kinds)))]
        if kind == "bad":
            field = list(_FIELDS)[int(rng.integers(len(_FIELDS)))]
            pool = _FIELDS[field] + _BAD_QUANTITY
            value = pool[int(rng.integers(len(pool)))]
            if field == "actuator.force_constant" and value is None:
                continue                       # optional: None is "not given"
            if value is None and field in ("forcing.phase", "sensor.resolution",
                                           "actuator.force_limit", "actuator.latency",
                                           "controller.pi2_offset"):
                continue                       # optional fields: None means the default
            _set(doc, field, value)
            named = field
        elif kind == "missing":
            field = required[int(rng.integers(len(required)))]
            _delete(doc, field)
            named = field
        elif kind == "unknown":
            where = ["", "forcing.", "sensor.", "actuator.", "controller."][int(rng.integers(5))]
            key = ["colour", "gap_mm", "Mass", "rate_hz", "bugdet", "1", "stop_"][int(rng.integers(7))]
            if where:
                doc[where[:-1]][key] = "1 m"
            else:
                doc[key] = "1 m"
            named = f"{where}{key}"
        elif kind == "number":
            field = list(_NUMBERS)[int(rng.integers(len(_NUMBERS)))]
            pool = _NUMBERS[field]
            value = pool[int(rng.integers(len(pool)))]
            _set(doc, field, value)
            named = field
        elif kind == "type":
            section = ["forcing", "sensor", "actuator", "controller"][int(rng.integers(4))]
            value = [["a"], "text", 5, 2.5, True][int(rng.integers(5))]
            doc[section] = value
            named = section
        else:
            case = int(rng.integers(8))
            if case == 0:      # base excitation with a ground-fixed stop
                doc["forcing"] = {"type": "base", "amplitude": "1 mm",
                                  "frequency": LAB["forcing"]["frequency"],
                                  "stop": ["ground", None, "frame_", 1][int(rng.integers(4))]}
                named = "forcing.stop"
            elif case == 1:    # a stop on a force rig
                doc["forcing"]["stop"] = "frame"
                named = "forcing.stop"
            elif case == 2:
                doc["forcing"]["type"] = ["Force", "torque", 1, None, []][int(rng.integers(5))]
                if doc["forcing"]["type"] is None:
                    continue                   # None: the default, force
                named = "forcing.type"
            elif case == 3:
                doc["sensor"]["measures"] = ["velocity", "pos", 2, []][int(rng.integers(4))]
                named = "sensor.measures"
            elif case == 4:    # both or neither of natural_frequency and stiffness
                if rng.random() < 0.5:
                    doc["stiffness"] = "7.9e3 N/m"
                else:
                    del doc["natural_frequency"]
                named = "natural_frequency / stiffness"
            elif case == 5:
                doc["sensor"]["velocity_noise"] = "1 mm/s"
                named = "sensor.velocity_noise"
            elif case == 6:
                doc["sensor"]["measures"] = "position_velocity"
                doc["sensor"]["velocity_noise"] = ["1 m", "-1 mm/s", 0.001, None, "x mm/s"][int(rng.integers(5))]
                named = "sensor.velocity_noise"
            else:
                doc["damping"] = "1 N*s/m"
                named = "damping_ratio / damping"
        out.append((f"{kind}: {named}", doc, named))
    return out


#: Whole files that are not rig files (text, the field or word the refusal names).
HOSTILE_TEXTS = [
    ("", "not a mapping"),
    ("- 1\n- 2\n", "not a mapping"),
    ("just text\n", "not a mapping"),
    ("mass: [unclosed\n", None),
    ("a: &a [x, x, x, x, x, x, x, x, x]\nb: &b [*a, *a, *a, *a, *a, *a, *a, *a, *a]\n"
     "c: &c [*b, *b, *b, *b, *b, *b, *b, *b, *b]\nd: &d [*c, *c, *c, *c, *c, *c, *c, *c, *c]\n"
     "e: &e [*d, *d, *d, *d, *d, *d, *d, *d, *d]\nf: &f [*e, *e, *e, *e, *e, *e, *e, *e, *e]\n",
     None),
    ("mass: !!python/object/apply:os.system ['true']\n", None),
    ("\xff\xfe bad utf8", None),
]
