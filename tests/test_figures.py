"""Specification tests of grazing_control.studies.figures and `grazing figures` (issue 10 §3).

One quick run (``--quick``: every panel, coarse grids) through the command line is
shared by the tests; its numbers (figures.json, rendered into figures.md) are checked
against the core computed here independently of the figures code:

* the period doubling against a fresh continuation on another grid, and against the
  brute-force diagram (the exact point must lie between the last period-1 and the
  first period-2 grid point);
* the admissible c2 set and c1 against design.py;
* the power laws against theory (slopes -1, 1, 1/2);
* the control scenes against the exact controlled 1/1 orbit.
"""

import json
import math
import subprocess
import sys

import numpy as np
import pytest

from grazing_control.cli import main
from grazing_control.dynamics.orbits.continuation import continue_11
from grazing_control.dynamics.design.gains import admissible_c2, degenerate_c1, evaluate_design
from grazing_control.support.plotting import stability_segments
from grazing_control.studies.figures.branches import loglog_slope
from grazing_control.oscillator.params import OscillatorParams

PANELS = ("fig1a", "fig1b", "fig1c", "fig1d", "fig2a", "fig2b", "fig2c", "fig2d", "fig2e",
          "fig2f", "fig2g")


@pytest.fixture(scope="module")
def quick(tmp_path_factory):
    out = tmp_path_factory.mktemp("figures")
    code = main(["figures", "--quick", "--out", str(out), "--workers", "1", "--json",
                 "--docs", str(out / "docs")])
    assert code == 0
    doc = json.loads((out / "figures.json").read_text(encoding="utf-8"))
    md = (out / "figures.md").read_text(encoding="utf-8")
    return out, doc, md


def test_every_panel_is_written_as_png_and_svg_and_shown_in_figures_md(quick):
    out, doc, md = quick
    assert sorted(doc["panels"]) == sorted(PANELS)
    for name in PANELS:
        png, svg = out / f"{name}.png", out / f"{name}.svg"
        assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
        assert png.stat().st_size > 10_000  # drawn, not blank
        assert svg.read_text(encoding="utf-8").lstrip().startswith("<?xml")
        assert f"]({name}.png)" in md
    assert doc["mode"] == "quick"


def test_docs_get_small_thumbnails_and_the_same_numbers(quick):
    out, doc, md = quick
    docs_md = (out / "docs" / "figures.md").read_text(encoding="utf-8")
    for name in PANELS:
        thumb = out / "docs" / "img" / "figures" / f"{name}.png"
        assert 5_000 < thumb.stat().st_size < 200_000
        assert f"](img/figures/{name}.png)" in docs_md
    assert "grazing figures --quick --docs" in docs_md
    # the same tables as figures.md
    assert [ln for ln in docs_md.splitlines() if ln.startswith("| ")] == \
        [ln for ln in md.splitlines() if ln.startswith("| ")]


def test_the_period_doubling_is_the_continuation_s(quick):
    _out, doc, md = quick
    p = OscillatorParams()
    pd = [b for b in continue_11(p, -2e-4, -1e-9, points=57).bifurcations
          if b.type == "period-doubling"]
    assert len(pd) == 1
    for panel in ("fig1b", "fig1c", "fig1d"):
        assert doc["panels"][panel]["pd_delta_d"] == pytest.approx(pd[0].delta_d, rel=1e-12)
    assert f"{doc['panels']['fig1c']['pd_delta_d']:.12g}" in md
    # the study's value, to the digits it gives
    assert round(doc["panels"]["fig1c"]["pd_delta_d"], 10) == -1.00527e-5


def test_brute_force_diagram_doubles_where_the_branch_loses_stability(quick):
    nums = quick[1]["panels"]["fig1b"]
    assert nums["brute_last_period1"] <= nums["pd_delta_d"] <= nums["brute_first_period2"]
    assert nums["pd_in_bracket"] is True
    assert nums["brute_first_period2"] < nums["brute_first_period4"] < nums["brute_chaos_from"]
    # the period-1 points of the diagram are the exact 1/1 orbit, the period-2 points the
    # 2/2 orbit found by Newton shooting; period 4 appears only past the 2/2 orbit's doubling
    assert quick[1]["panels"]["fig1a"]["branch_agreement"] < 1e-10
    assert nums["two_cycle_agreement"] < 1e-10
    assert nums["brute_first_period2"] < nums["two_cycle_pd"] <= nums["brute_first_period4"]


def test_admissible_set_and_gains_are_design_s(quick):
    nums = quick[1]["panels"]["fig2a"]
    p = OscillatorParams()
    (lo, hi), = admissible_c2(p)
    assert nums["admissible_c2"] == [lo, hi]
    assert nums["c1_at_chosen"] == degenerate_c1(p, -1.0)
    assert round(nums["c1_at_chosen"], 5) == -1.02060
    assert nums["admissible_c2_perturbation"] == pytest.approx([lo, hi], abs=1e-8)
    # each end of the set is where a drawn constraint is marginal
    assert "none" not in nums["admissible_ends_binding"]
    assert nums["admissible_ends_binding"].startswith("|λ0| = 1")  # the lower end: a flip
    zero = quick[1]["panels"]["fig2b"]["gamma1_zero"]
    assert evaluate_design(p, zero).gamma1 == pytest.approx(0.0, abs=1e-9)
    assert hi <= zero + 1e-9  # gamma1 > 0 inside the set


def test_power_laws_read_off_the_panels_match_theory(quick):
    panels = quick[1]["panels"]
    assert panels["fig1d"]["slope"] == pytest.approx(-1.0, abs=1e-3)
    assert panels["fig1c"]["v_minus_slope"] == pytest.approx(1.0, abs=1e-3)
    assert panels["fig2c"]["controlled_v_minus_slope"] == pytest.approx(0.5, abs=1e-3)
    assert panels["fig2e"]["slope"] == pytest.approx(0.5, abs=1e-3)
    assert panels["fig1d"]["perturbation_rel_error_near"] < 1e-8


def test_controlled_branch_is_stable_and_bounded(quick):
    panels = quick[1]["panels"]
    assert panels["fig2c"]["controlled_all_stable"] is True
    assert panels["fig2c"]["controlled_bifurcations"] == "none"
    assert panels["fig2d"]["max_abs_multiplier"] < panels["fig2d"]["lambda0"][0] + 1e-12
    assert panels["fig2d"]["lambda0_perturbation"] == pytest.approx(panels["fig2d"]["lambda0"],
                                                                    abs=1e-9)


@pytest.mark.parametrize("panel,delta_d", [("fig2f", -5e-6), ("fig2g", -9e-6)])
def test_control_scenes_converge_to_the_exact_controlled_orbit(quick, panel, delta_d):
    nums = quick[1]["panels"][panel]
    assert nums["delta_d"] == delta_d
    assert nums["control_on"] == 1000
    assert nums["one_impact_per_period"] is True
    assert nums["final_error"] < 1e-10
    assert nums["samples_to_converge"] < 100


def test_numbers_in_figures_md_are_those_of_figures_json(quick):
    _out, doc, md = quick
    rows = [ln for ln in md.splitlines() if ln.startswith("| ")]
    # four cells per row: a '|' inside a cell (|λ|) is escaped
    assert rows and all(len(ln.replace("\\|", "").split("|")) == 6 for ln in rows)
    nums = doc["panels"]
    assert f"{nums['fig2a']['admissible_c2'][0]:.10g}" in md
    assert f"{nums['fig2f']['final_error']:.2e}" in md
    assert f"{nums['fig1d']['slope']:.5f}" in md


def _status(argv):
    try:
        return main(argv)
    except SystemExit as exc:  # argparse's own errors
        return exc.code


@pytest.mark.parametrize("argv,needle", [
    (["--workers", "0"], "--workers"),
    (["--workers", "x"], "--workers"),
    (["--bags", "/nonexistent/bags"], "bags"),
    (["--out", ""], "--out"),
    (["--out", "  "], "--out"),
    (["--docs", ""], "--docs"),
])
def test_bad_input_is_one_line_and_status_2(tmp_path, capsys, monkeypatch, argv, needle):
    monkeypatch.chdir(tmp_path)
    assert _status(["figures", "--quick", "--out", str(tmp_path / "o")] + argv) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("grazing: error:") and needle in err and "\n" not in err
    assert list(tmp_path.iterdir()) == []  # nothing written, not even into the cwd


def test_out_that_is_a_file_is_refused(tmp_path, capsys):
    target = tmp_path / "file"
    target.write_text("keep")
    assert _status(["figures", "--quick", "--out", str(target)]) == 2
    assert "--out" in capsys.readouterr().err
    assert target.read_text() == "keep"


def test_stability_segments_split_and_share_end_points():
    x = np.arange(6.0)
    segs = stability_segments(x, x ** 2, [True, True, False, False, True, True])
    assert [s[2] for s in segs] == [True, False, True]
    assert [list(s[0]) for s in segs] == [[0, 1, 2], [2, 3, 4], [4, 5]]
    assert stability_segments([], [], []) == []


def test_loglog_slope_of_exact_power_laws():
    x = -np.logspace(-12, -3, 50)
    for s in (-1.0, 0.5, 2.0):
        assert loglog_slope(x, 3.0 * np.abs(x) ** s, 1e-12, 1e-8) == pytest.approx(s, abs=1e-12)
    assert math.isnan(loglog_slope(x, x, 1.0, 2.0))


def test_the_figures_never_import_rclpy():
    code = ("import sys, grazing_control.studies.figures, grazing_control.studies.figures.command; "
            "sys.exit('rclpy' in sys.modules)")
    assert subprocess.run([sys.executable, "-c", code]).returncode == 0


def _record_scene(bag_dir, res):
    """Write a core simulation as the nodes would record it (docs/recording.md topics)."""
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import TwistStamped, Vector3Stamped
    from mcap_ros2._dynamic import serialize_dynamic
    from sensor_msgs.msg import JointState

    from grazing_control.ros.recording import BagWriter, message_definition, qos_profile_dict

    def stamp(t):
        ns = round(t * 1e9)
        return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    topics = {"/oscillator/pi2": "sensor_msgs/msg/JointState",
              "/controller/velocity_correction": "geometry_msgs/msg/TwistStamped",
              "/oscillator/impact": "geometry_msgs/msg/Vector3Stamped"}
    enc = {t: serialize_dynamic(t, message_definition(t))[t] for t in topics.values()}
    qos = [qos_profile_dict(history="keep_all", reliability="reliable")]
    period = res.params.period
    with BagWriter(bag_dir) as bag:
        for topic, kind in topics.items():
            bag.add_topic(topic, kind, qos)
        n = 0
        for k, (x, v) in enumerate(res.pi2):
            s = JointState(name=["mass"], position=[float(x)], velocity=[float(v)])
            s.header.stamp = stamp(k * period)
            c = TwistStamped()
            c.header.stamp = s.header.stamp
            c.twist.linear.x = float(res.corrections[k])
            for topic, msg in (("/oscillator/pi2", s), ("/controller/velocity_correction", c)):
                n += 1
                bag.write(topic, enc[topics[topic]](msg), n, n, sequence=n)
        for _k, t, phase, vm, vp in res.impacts:
            m = Vector3Stamped()
            m.header.stamp = stamp(t)
            m.vector.x, m.vector.y, m.vector.z = float(vm), float(vp), float(phase)
            n += 1
            bag.write("/oscillator/impact", enc[topics["/oscillator/impact"]](m), n, n, sequence=n)


def test_a_scene_panel_reads_a_recording_when_given_one(tmp_path):
    from grazing_control.oscillator.control import Gains
    from grazing_control.studies.demo import CONTROL_AFTER, PERIODS
    from grazing_control.studies.figures.scenes import panel_scene
    from grazing_control.dynamics.simulation.simulate import simulate

    p = OscillatorParams()
    gains = Gains(degenerate_c1(p, -1.0), -1.0)
    res = simulate(p.with_(delta_d=-9e-6), PERIODS, gains=gains, control_after=CONTROL_AFTER)
    _record_scene(tmp_path / "bags" / "scene_9e-6", res)
    from_bag = panel_scene(p, gains, "g", tmp_path, bags=tmp_path / "bags")
    from_core = panel_scene(p, gains, "g", tmp_path)
    got = {n.key: n.value for n in from_bag.numbers}
    want = {n.key: n.value for n in from_core.numbers}
    assert got.pop("source").startswith("recording ") and want.pop("source") == "core simulation"
    assert got["final_error"] < 1e-10 and want["final_error"] < 1e-10
    assert {k: v for k, v in got.items() if k != "final_error"} == \
        {k: v for k, v in want.items() if k != "final_error"}
    assert (tmp_path / "fig2g.png").exists()


def test_the_controlled_non_impacting_motion_is_marginal_at_the_ends_read_off_fig2a(quick):
    """At the ends of the c2 range where the controlled 0/1 motion is stable, N_g (built
    here from scipy's expm, not the closed-form Phi) has a multiplier on the unit circle."""
    from scipy.linalg import expm

    p = OscillatorParams()
    a = np.array([[0.0, 1.0], [-1.0, -2.0 * p.zeta]])
    s = p.pi2_offset / p.omega
    for c2 in quick[1]["panels"]["fig2a"]["free_stable_c2"]:
        g = np.array([[1.0, 0.0], [degenerate_c1(p, c2), 1.0 + c2]])
        n_g = expm(a * (p.period - s)) @ g @ expm(a * s)
        assert np.max(np.abs(np.linalg.eigvals(n_g))) == pytest.approx(1.0, abs=1e-9)
