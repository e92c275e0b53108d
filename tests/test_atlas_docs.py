"""The atlas's files as documented (issue 27 §3): each help text names every column and
array that a real small run of its command writes (read from the files, not from a list
copied here); the controlled omega plane's four degenerate points (`grazing continue2
--c2 -1`) are checked by an independent evaluation; a curve that runs into the
controller's kick phase ends there, named so."""

import csv
import json
import math
import re

import numpy as np
import pytest

from grazing_control.cli.commands import build_parser, main
from grazing_control.dynamics.design.gains import degenerate_c1
from grazing_control.dynamics.maps.maps import period_matrix, transition_matrix
from grazing_control.dynamics.orbits.two_parameter import KINDS, Family, continue_curve
from grazing_control.oscillator.control import Gains
from grazing_control.oscillator.params import OscillatorParams

P = OscillatorParams()
C1 = degenerate_c1(P, -1.0)          # the study's design: c1 from Eq. 38 at c2 = -1


def help_text(capsys, command):
    with pytest.raises(SystemExit):
        build_parser().parse_args([command, "--help"])
    return " ".join(capsys.readouterr().out.split())


def named(text, name):
    return re.search(rf"(?<![\w-]){re.escape(name)}(?![\w-])", text) is not None


@pytest.fixture(scope="module")
def controlled(tmp_path_factory):
    out = tmp_path_factory.mktemp("continue2")
    import contextlib
    import io
    buf = io.StringIO()
    with contextlib.redirect_stdout(buf):
        assert main(["continue2", "--c2", "-1", "--max-points", "5", "--json",
                     "--out", str(out)]) == 0
    return json.loads(buf.getvalue()), out


def test_continue2_help_names_every_csv_column(capsys, controlled):
    _, out = controlled
    with open(out / "continue2_curves.csv", newline="") as fh:
        header = next(csv.reader(fh))
    text = help_text(capsys, "continue2")
    assert header[2] == "omega" and len(header) == 10
    missing = [c for c in header if not named(text, c)]
    assert not missing, missing
    for end in ("grazing", "unphysical side", "range", "points", "controller phase",
                "step size"):
        assert end in text


def test_the_four_degenerate_points_of_the_controlled_omega_plane(controlled):
    # With c2 = -1 the kick sets v to c1 x, so N_g,12 = Phi12(s) (Phi11(t) + c1 Phi12(t)),
    # s = pi2_offset / omega, t = T - s (docs/theory_two_parameter.md, section 5): zero
    # where omega_d s = pi (m = 4 of the uncontrolled plane, any c1) and where
    # tan(omega_d t) = -omega_d / (zeta + c1), t = (2 pi - pi2_offset) / omega.
    doc, _ = controlled
    found = [c["value"] for c in doc["codim2"]]
    wd, z, off = P.omega_d, P.zeta, P.pi2_offset
    phase = math.atan(-wd / (z + C1)) % math.pi
    closed = sorted([wd * off / math.pi]
                    + [wd * (2 * math.pi - off) / (phase + k * math.pi) for k in (1, 2, 3)])
    assert all(0.45 < w < 2.1 for w in closed)
    assert wd * (2 * math.pi - off) / (phase + 4 * math.pi) < 0.45 < 2.1 < \
        wd * (2 * math.pi - off) / phase                        # and no other in range
    assert np.max(np.abs(np.array(found) - closed)) < 1e-12, (found, closed)
    for w in found:
        p = P.with_(omega=w)
        s = p.pi2_offset / w
        assert abs(period_matrix(p, Gains(C1, -1.0))[1]) < 1e-14   # Eq. 33 at the point
        if abs(transition_matrix(p.zeta, s)[1]) < 1e-12:
            assert abs(w - 2 * wd / 4) < 1e-14       # Phi12(s) = 0: no c1 is needed
        else:   # the design condition (Eq. 38) at that omega gives back the held c1
            assert abs(degenerate_c1(p, -1.0) - C1) < 1e-12
    assert abs(found[2] - P.omega) < 1e-15       # the design point itself


def test_a_fold_curve_running_into_the_kick_phase_ends_there():
    # the fold curve from the degenerate point omega = 1.2016 runs into psi = pi/2, the
    # impact at the instant of the kick, where the 1/1 branch jumps: it ended with
    # "step size" before (issue 27), every step across pi/2 refused
    fam = Family(P, Gains(C1, -1.0), "omega")
    curve = continue_curve(fam, KINDS[1], 0.0, 1.2015609711321371, 0.45, 2.1)
    assert curve.ends == ("unphysical side (v- < 0)", "controller phase")
    last = curve.points[-1]
    assert 0.0 < math.pi / 2 - last.psi < 1e-5 and abs(last.value - 1.3223847) < 1e-6


def test_sweep_help_names_every_npz_array(capsys, tmp_path):
    out = tmp_path / "s.npz"
    assert main(["sweep", "--grid", "delta_d=-5e-6,-4e-6", "--c2", "-1", "--periods", "20",
                 "--lyapunov", "--no-png", "--workers", "1", "--json", "--out", str(out)]) == 0
    capsys.readouterr()
    with np.load(out) as f:
        arrays = {re.sub(r"^(axis|point)_delta_d$", r"\1_NAME", n) for n in f.files}
        lyap = f["lyapunov"]
        meta = json.loads(str(f["meta"]))
    text = help_text(capsys, "sweep")
    missing = [n for n in arrays if not named(text, n)]
    assert not missing, missing
    assert all(named(text, k) for k in meta if k != "format")
    # per forcing period, largest first; c2 = -1 makes the map singular: the second -inf
    assert "per forcing period" in text and "largest first" in text
    assert np.all(lyap[:, 0] >= lyap[:, 1]) and np.all(lyap[:, 1] == -np.inf)


def test_basins_help_names_every_npz_array(capsys, tmp_path):
    stem = tmp_path / "b"
    assert main(["basins", "--delta-d", "-5e-6", "--nx", "2", "--nv", "2", "--transient",
                 "10", "--max-period", "2", "--workers", "1", "--no-png", "--json",
                 "--out", str(stem)]) == 0
    capsys.readouterr()
    with np.load(f"{stem}.npz") as f:
        arrays = {re.sub(r"^attractor_points_\d+$", "attractor_points_J", n) for n in f.files}
    text = help_text(capsys, "basins")
    missing = [n for n in arrays if not named(text, n)]
    assert not missing, missing
