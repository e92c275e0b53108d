"""Hostile parameter records and scene folders: a record whose values are not numbers, a
100,000-deep JSON text on ``grazing/parameters``, a garbage scene folder for the figures.
Each is listed under what cannot be used (or refused with one line, status 2); the rest of
the analysis gives the numbers of the unaltered bag."""

import json
import struct
import subprocess
import sys

import pytest
from mcap.reader import make_reader

from grazing_control.ros.recording import BagWriter
from grazing_control.ros.recording.record import decode

from bagtools_helpers import BAGS

SOURCE = BAGS / "scene_5e-6" / "scene_5e-6_0.mcap"


def _string_cdr(text: str) -> bytes:
    raw = text.encode() + b"\0"
    return b"\x00\x01\x00\x00" + struct.pack("<I", len(raw)) + raw


def _rewrite(folder, alter):
    """A copy of the reference bag with each parameter record's text passed through alter
    (which returns a list of texts to write in its place)."""
    with open(SOURCE, "rb") as fh, BagWriter(folder, compression="zstd") as w:
        for schema, channel, msg in make_reader(fh).iter_messages():
            if not w.has_topic(channel.topic):
                w.add_topic(channel.topic, schema.name)
            if channel.topic == "/grazing/parameters":
                n = struct.unpack_from("<I", msg.data, 4)[0]
                text = msg.data[8:8 + n].rstrip(b"\0").decode()
                for new in alter(text):
                    w.write(channel.topic, _string_cdr(new), msg.log_time)
            else:
                w.write(channel.topic, msg.data, msg.log_time)
    return folder


def _analyze(bag, tmp_path):
    out = subprocess.run([sys.executable, "-m", "grazing_control.cli", "analyze", str(bag),
                          "--json", "--no-figures", "--out", str(tmp_path / "report")],
                         capture_output=True, text=True, timeout=300)
    return out


@pytest.fixture(scope="module")
def clean_report(tmp_path_factory):
    tmp = tmp_path_factory.mktemp("clean")
    out = _analyze(_rewrite(tmp / "clean", lambda t: [t]), tmp)
    assert out.returncode == 0, out.stderr
    return json.loads(out.stdout)


def _contraction(report):
    return report["bags"][0]["scenes"][0]["measured_contraction"]


def test_a_deeply_nested_record_is_rejected_not_fatal():
    with pytest.raises(ValueError, match="nested too deeply"):
        decode("[" * 100_000 + "]" * 100_000)


def test_a_deeply_nested_message_is_listed_and_the_analysis_goes_on(tmp_path, clean_report):
    bomb = "[" * 100_000 + "]" * 100_000
    out = _analyze(_rewrite(tmp_path / "deep", lambda t: [bomb, t]), tmp_path)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert any("not parameter records" in p for p in report["bags"][0]["problems"])
    assert report["bags"][0]["setup"] == clean_report["bags"][0]["setup"]
    assert _contraction(report) == _contraction(clean_report)


def test_gains_that_are_not_numbers_are_ignored_with_a_note(tmp_path, clean_report):
    def alter(text):
        obj = json.loads(text)
        if obj["node"].endswith("controller_node"):
            obj["parameters"]["c1"] = [1, 2, 3]
            obj["parameters"]["c2"] = {"x": 1}
        return [json.dumps(obj)]

    out = _analyze(_rewrite(tmp_path / "lists", alter), tmp_path)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)
    assert any("not a number" in n for n in report["bags"][0]["notes"])
    gains = report["bags"][0]["setup"]["gains"]
    assert "inferred by least squares" in report["bags"][0]["setup"]["sources"]["gains"]
    assert gains["c1"] == pytest.approx(clean_report["bags"][0]["setup"]["gains"]["c1"], rel=1e-9)
    assert gains["c2"] == pytest.approx(-1.0, rel=1e-9)
    assert _contraction(report)["rho"] == pytest.approx(_contraction(clean_report)["rho"],
                                                        rel=1e-9)


@pytest.mark.parametrize("garbage", ["random", "empty_bag", "no_pi2_arrays"])
def test_a_garbage_scene_folder_for_the_figures_is_one_line_status_2(tmp_path, garbage):
    bags = tmp_path / "bags"
    folder = bags / "scene_5e-6"
    folder.mkdir(parents=True)
    if garbage == "random":
        (folder / "scene_5e-6_0.mcap").write_bytes(bytes(range(256)) * 40)
    else:
        with BagWriter(folder) as w:
            w.add_topic("/oscillator/pi2", "sensor_msgs/msg/JointState")
            if garbage == "no_pi2_arrays":     # a JointState with empty position/velocity
                body = (b"\x00\x01\x00\x00" + struct.pack("<iI", 1, 0) + struct.pack("<I", 1)
                        + b"\0" + b"\0" * 3 + struct.pack("<IIII", 0, 0, 0, 0))
                w.write("/oscillator/pi2", body, 1)
    out = subprocess.run([sys.executable, "-m", "grazing_control.cli", "figures", "--quick",
                          "--bags", str(bags), "--out", str(tmp_path / "fig")],
                         capture_output=True, text=True, timeout=600)
    assert out.returncode == 2, (out.stdout[-2000:], out.stderr[-2000:])
    assert "Traceback" not in out.stderr
    assert len(out.stderr.strip().splitlines()) == 1, out.stderr
