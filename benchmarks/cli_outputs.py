"""Every model command's output on a fixed set of options, saved and compared (issue 32's
fold of the model commands: each command's 1-DOF and n-DOF output must not change).

    python benchmarks/cli_outputs.py save DIR      # run every case, write DIR/<case>.txt
    python benchmarks/cli_outputs.py compare DIR   # run again, diff against DIR

Each case runs ``python -m grazing_control.cli ...`` with single-threaded BLAS and
records stdout, stderr and the exit status. Wall times and rates (JSON ``seconds``,
``periods_per_second``, text "0.12 s", "42 periods/s")
and the case's scratch folder are masked; everything else must match byte for byte.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import tempfile
from concurrent.futures import ThreadPoolExecutor

ONE = "config/models/study_1dof.yaml"
TWO = "config/models/two_mass_chain.yaml"

CASES = {
    # 1-DOF commands
    "design": ["design", "--c2", "-1"],
    "design_json": ["design", "--c2", "-1", "--json"],
    "design_delay_json": ["design", "--c2", "-0.5", "--delay", "2", "--json"],
    "orbit": ["orbit", "--delta-d", "-1e-4"],
    "orbit_json": ["orbit", "--delta-d", "-1e-6", "--json"],
    "orbit_ctl": ["orbit", "--delta-d", "-1e-6", "--c2", "-1"],
    "orbit_ctl_delay_json": ["orbit", "--delta-d", "-1e-6", "--c2", "-1", "--delay", "2", "--json"],
    "continue": ["continue", "--from", "-1e-3", "--to", "-1e-6", "--points", "30"],
    "continue_json": ["continue", "--from", "-1e-3", "--to", "-1e-6", "--points", "30", "--c2", "-1", "--json"],
    "simulate": ["simulate", "--delta-d", "-5e-6", "--periods", "40"],
    "simulate_ctl_json": ["simulate", "--delta-d", "-5e-6", "--periods", "40", "--c2", "-1",
                          "--control-after", "20", "--json"],
    "sweep": ["sweep", "--grid", "delta_d=-1e-4:-1e-5:3", "--periods", "20", "--workers", "1",
              "--out", "{tmp}/s1"],
    "sweep_json": ["sweep", "--grid", "delta_d=-1e-4:-1e-5:3", "--periods", "20", "--workers", "1",
                   "--out", "{tmp}/s1", "--no-png", "--json"],
    # the design's other reports (issue 32: one report for both models)
    "design_pulse_json": ["design", "--c2", "-0.5", "--delay", "1", "--pulse-width", "0.5", "--json"],
    "design_actuator": ["design", "--c2", "-0.5", "--delay", "1", "--pulse-width", "0.5",
                        "--actuator-bandwidth", "5", "--actuator-latency", "0.1", "--delta-d", "-1e-5"],
    "design_optimize_json": ["design", "--optimize", "noise", "--json"],
    "design_perturbation": ["design", "--c2", "-0.5", "--method", "perturbation"],
    "design_out": ["design", "--c2", "-0.5", "--out", "{tmp}/d1.yaml"],
    "orbit_perturbation": ["orbit", "--delta-d", "-1e-4", "--c2", "-0.5", "--method", "perturbation"],
    "continue_delay": ["continue", "--from", "-1e-2", "--to", "-1e-8", "--points", "9", "--c2", "-0.5",
                       "--delay", "0.5"],
    # n-DOF commands, the n = 1 and the 2-mass model files
    "m1_design": ["design", "--model", ONE, "--free-gain", "v0=-1"],
    "m1_design_json": ["design", "--model", ONE, "--free-gain", "v0=-1", "--json"],
    "m2_design": ["design", "--model", TWO],
    "m2_design_json": ["design", "--model", TWO, "--mu", "0.2", "--json"],
    "m2_design_delay": ["design", "--model", TWO, "--delay", "4", "--mu", "0"],
    "m1_orbit_json": ["orbit", "--model", ONE, "--delta-d", "-1e-6", "--json"],
    "m2_orbit": ["orbit", "--model", TWO, "--delta-d", "-1e-6", "--mu", "0.2"],
    "m2_orbit_json": ["orbit", "--model", TWO, "--delta-d", "-1e-6", "--json"],
    "m2_continue": ["continue", "--model", TWO, "--from", "-1e-4", "--to", "-1e-8", "--points", "8",
                    "--mu", "0.2"],
    "m2_continue_json": ["continue", "--model", TWO, "--from", "-1e-4", "--to", "-1e-8", "--points",
                         "8", "--json"],
    "m1_continue_json": ["continue", "--model", ONE, "--from", "-1e-3", "--to", "-1e-6", "--points",
                         "10", "--json"],
    "m2_simulate": ["simulate", "--model", TWO, "--delta-d", "-5e-6", "--periods", "40", "--mu",
                    "0.2", "--control-after", "20"],
    "m1_simulate_json": ["simulate", "--model", ONE, "--delta-d", "-5e-6", "--periods", "40",
                         "--json"],
    "m2_sweep": ["sweep", "--model", TWO, "--grid", "delta_d=-1e-4:0:3", "--periods", "10",
                 "--workers", "1", "--out", "{tmp}/s2"],
    "m2_sweep_json": ["sweep", "--model", TWO, "--grid", "delta_d=-1e-4:0:3", "--periods", "10",
                      "--workers", "1", "--out", "{tmp}/s2", "--no-png", "--json"],
    "m2_figures_json": ["figures", "--model", TWO, "--quick", "--workers", "1", "--out",
                        "{tmp}/f2", "--json"],
    "m2_design_pulse": ["design", "--model", TWO, "--mu", "0.2", "--delay", "1", "--pulse-width", "0.5"],
    "m2_orbit_delay": ["orbit", "--model", TWO, "--delta-d", "-1e-4", "--mu", "0.2", "--delay", "0.5"],
    "m2_sweep_delay_json": ["sweep", "--model", TWO, "--grid", "delta_d=-1e-4:-1e-5:3", "--periods", "10",
                            "--mu", "0.2", "--delay", "0.5", "--workers", "1", "--out", "{tmp}/s3",
                            "--no-png", "--json"],
    # refusals
    "err_c2_with_model": ["orbit", "--model", ONE, "--delta-d", "-1e-6", "--c2", "-1"],
    "err_mu_without_model": ["orbit", "--delta-d", "-1e-6", "--mu", "0"],
    "err_gains_size": ["orbit", "--model", TWO, "--delta-d", "-1e-6", "--gains", "1,2,3"],
    "err_z0": ["simulate", "--model", TWO, "--delta-d", "-1e-6", "--periods", "3", "--z0", "1,2"],
    "err_free_gain": ["orbit", "--model", TWO, "--delta-d", "-1e-6", "--free-gain", "q3=1"],
    "err_delay_range": ["design", "--model", TWO, "--delay", "12"],
    "err_sweep_grid": ["sweep", "--model", TWO, "--grid", "zeta=0.1:0.2:2", "--periods", "3"],
    "err_points": ["continue", "--model", TWO, "--from", "-1e-4", "--to", "-1e-8", "--points", "1"],
    "help_design": ["design", "--help"],
    "help_orbit": ["orbit", "--help"],
    "help_continue": ["continue", "--help"],
    "help_simulate": ["simulate", "--help"],
    "help_sweep": ["sweep", "--help"],
    "help_figures": ["figures", "--help"],
}

_SECONDS = re.compile(r"\d+(\.\d+)?(e[-+]?\d+)? (s\b|periods/s)")


def _mask(text: str, tmp: str) -> str:
    text = text.replace(tmp, "{tmp}")
    out = []
    for line in text.splitlines():
        try:
            obj = json.loads(line)
        except ValueError:
            out.append(_SECONDS.sub(r"<t> \3", line))
            continue
        out.append(json.dumps(_drop_seconds(obj), sort_keys=True, indent=0))
    return "\n".join(out)


def _drop_seconds(obj):
    if isinstance(obj, dict):
        return {k: _drop_seconds(v) for k, v in obj.items() if k not in ("seconds", "time_s", "periods_per_second")}
    if isinstance(obj, list):
        return [_drop_seconds(v) for v in obj]
    return obj


def run_case(name: str) -> str:
    with tempfile.TemporaryDirectory() as tmp:
        argv = [a.replace("{tmp}", tmp) for a in CASES[name]]
        env = dict(os.environ, OPENBLAS_NUM_THREADS="1", OMP_NUM_THREADS="1", COLUMNS="100")
        p = subprocess.run([sys.executable, "-m", "grazing_control.cli", *argv],
                           capture_output=True, text=True, env=env, timeout=900)
        return (f"$ grazing {' '.join(CASES[name])}\nstatus {p.returncode}\n--- stdout\n"
                f"{_mask(p.stdout, tmp)}\n--- stderr\n{_mask(p.stderr, tmp)}\n")


def main(argv) -> int:
    what, folder = argv[1], argv[2]
    names = argv[3:] or list(CASES)
    with ThreadPoolExecutor(2) as pool:
        results = dict(zip(names, pool.map(run_case, names)))
    if what == "save":
        os.makedirs(folder, exist_ok=True)
        for name, text in results.items():
            with open(os.path.join(folder, name + ".txt"), "w", encoding="utf-8") as fh:
                fh.write(text)
        return 0
    bad = 0
    for name, text in results.items():
        with open(os.path.join(folder, name + ".txt"), encoding="utf-8") as fh:
            if fh.read() != text:
                bad += 1
                print(f"DIFFERS: {name}")
                with open(os.path.join(folder, name + ".new.txt"), "w", encoding="utf-8") as g:
                    g.write(text)
    print(f"{len(results) - bad} of {len(results)} cases identical")
    return 1 if bad else 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
