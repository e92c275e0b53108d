"""Issue 32's acceptance scene: the 2-DOF rig scene with a force pulse through the nodes,
and `grazing identify` on its bags (docs/ndof_scene.md, "The rig scene with a pulse").

The scene is benchmarks/ndof_stream_scene.py's (the shipped chain
config/models/two_mass_chain.yaml at Delta d = -1e-3, x0's position only at sigma 1e-4
and T/200, the controller's stream estimator, sim_node + controller_node + recorder)
with the correction acting as a **force pulse** of width ``--pulse-width`` (default 1.0)
on x1 centred ``--delay`` (1.0) after each sample, the delay-and-pulse-aware design
(``pulse_design``, `grazing design --model M --delay 1 --pulse-width 1`), the pulse
in the plant, the filter and the prediction (docs/theory_ndof.md section 15). It runs
``--node-seeds`` sensor seeds (7, 8, ...) in ``--mode`` (lockstep or realtime at
``--time-scale``) and prints, per seed, captured / impacts per period / spread over the
predicted spread (the design's: the loop's noise gain over the n-DOF map with the pulse,
dynamics/design/noise.py, what `grazing design --model M ... --delta-d D` prints;
docs/theory_ndof.md section 17). With ``--actuator-bandwidth B --actuator-latency L``
the pulse goes through the first-order actuator in the design, the plant, the filter
and the prediction (the loop's state (z, F)). With
``--identify`` each bag is identified (`grazing identify BAG --json`) and the fit's
(value - true) / stderr printed for every modal parameter and Delta d.

    .venv/bin/python benchmarks/ndof_rig_scene.py --node-seeds 3 --identify
    .venv/bin/python benchmarks/ndof_rig_scene.py --node-seeds 3 --seeds 2 --periods 400 \
        --identify --actuator-bandwidth 10 --actuator-latency 0.05
    .venv/bin/python benchmarks/ndof_rig_scene.py --node-seeds 2 --mode realtime --time-scale 10 \
        --periods 160 --settle 40 --seeds 0
"""

from __future__ import annotations

import argparse
import contextlib
import dataclasses
import io
import json
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parent
sys.path.insert(0, str(ROOT))

import ndof_stream_scene  # noqa: E402

#: What the rig scene sets unless given (the rest is ndof_stream_scene's).
RIG_DEFAULTS = {"--pulse-width": "1.0", "--node-seeds": "3", "--seeds": "2"}


def identify_z(bag: Path, model) -> dict:
    """`grazing identify BAG --json` (the n-DOF modal fit) and (fit - true) / stderr of
    every modal parameter of the wall coordinate (modal_of the true model) and Delta d."""
    from grazing_control import cli
    from grazing_control.dynamics.identification.modal import ModalLayout, modal_of

    out, err = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(out), contextlib.redirect_stderr(err):
        try:
            status = cli.main(["identify", str(bag), "--json"])
        except SystemExit as exc:
            status = exc.code
    if status not in (0, None):
        return {"status": status, "error": (err.getvalue() or out.getvalue()).strip()}
    report = json.loads(out.getvalue())
    layout = ModalLayout(model.n, actuator=report.get("kick_response") == "fitted")
    par = report["parameters"]
    z = {name: (par[name]["value"] - value) / par[name]["stderr"]
         for name, value in zip(layout.names, modal_of(model).vector(layout))}
    z["delta_d"] = (par["delta_d"]["value"] - model.delta_d) / par["delta_d"]["stderr"]
    return {"status": 0, "fit": report["fit"], "sigma": report["residuals"]["sigma"],
            "impacts": report["impacts"], "z": z}


def main(argv=None):
    """The scene (ndof_stream_scene.main with the rig's defaults), then identify."""
    argv = list(sys.argv[1:] if argv is None else argv)
    ap = argparse.ArgumentParser(add_help=False)
    ap.add_argument("--identify", action="store_true")
    ap.add_argument("--keep-bags", default="")
    ap.add_argument("--out", default="")
    own, rest = ap.parse_known_args(argv)
    if "-h" in rest or "--help" in rest:
        print(__doc__)
        return ndof_stream_scene.main(["--help"])
    for key, value in RIG_DEFAULTS.items():
        if key not in rest:
            rest += [key, value]
    with tempfile.TemporaryDirectory() as tmp:
        bags = Path(own.keep_bags or tmp)
        out = ndof_stream_scene.main(rest + ["--keep-bags", str(bags)])
        if own.identify:
            from grazing_control.oscillator.ndof import load_model

            model = dataclasses.replace(load_model(out["model"]), delta_d=out["delta_d"])
            for row in out.get("nodes", []):
                row["identify"] = identify_z(bags / f"bag_{row['seed']}", model)
                print(f"identify seed {row['seed']}: {summary(row['identify'])}")
    if own.out:
        with open(own.out, "w") as fh:
            json.dump(out, fh, indent=1)
    return out


def summary(got: dict) -> str:
    """One line of :func:`identify_z`'s result."""
    if got["status"]:
        return f"status {got['status']}: {got['error']}"
    z = {k: round(float(v), 2) for k, v in got["z"].items()}
    return (f"fit {got['fit']}, sigma {got['sigma']:.3g}, {got['impacts']} impacts, "
            f"(fit - true) / se {z}, max |z| {max(abs(v) for v in z.values()):.2f}")


if __name__ == "__main__":
    main()
