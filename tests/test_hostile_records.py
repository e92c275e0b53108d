"""Hostile parameter records and scene folders: a record whose values are not numbers, a
100,000-deep JSON text on ``grazing/parameters``, a garbage scene folder for the figures.
Each is listed under what cannot be used (or refused with one line, status 2); the rest of
the analysis gives the numbers of the unaltered bag."""

import json
import os
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


# ------------------------------------------------------------------ altered data (§7)
def _rewrite_messages(folder, alter):
    """Copy of the reference bag; ``alter(topic, data, index_on_topic, total)`` returns
    (topic, data) or None to drop the message."""
    with open(SOURCE, "rb") as fh:
        messages = list(make_reader(fh).iter_messages())
    totals = {}
    for _s, ch, _m in messages:
        totals[ch.topic] = totals.get(ch.topic, 0) + 1
    seen = {}
    with BagWriter(folder, compression="zstd") as w:
        for schema, channel, msg in messages:
            i = seen[channel.topic] = seen.get(channel.topic, -1) + 1
            out = alter(channel.topic, msg.data, i, totals[channel.topic])
            if out is None:
                continue
            topic, data = out
            if not w.has_topic(topic):
                w.add_topic(topic, schema.name)
            w.write(topic, data, msg.log_time)
    return folder


def _joint_state_velocity_set(data: bytes, value: float) -> bytes:
    """The JointState with its velocity[0] replaced (CDR offsets read from the bytes)."""
    b = bytearray(data)
    p = 4 + 8
    n = struct.unpack_from("<I", b, p)[0]                   # frame_id
    p += 4 + n
    p = (p - 4 + 3) // 4 * 4 + 4
    names = struct.unpack_from("<I", b, p)[0]
    p += 4
    for _ in range(names):
        p = (p - 4 + 3) // 4 * 4 + 4
        p += 4 + struct.unpack_from("<I", b, p)[0]
    p = (p - 4 + 3) // 4 * 4 + 4
    npos = struct.unpack_from("<I", b, p)[0]
    p += 4
    p = (p - 4 + 7) // 8 * 8 + 4
    p += 8 * npos
    p = (p - 4 + 3) // 4 * 4 + 4
    assert struct.unpack_from("<I", b, p)[0] >= 1
    p += 4
    p = (p - 4 + 7) // 8 * 8 + 4
    struct.pack_into("<d", b, p, value)
    return bytes(b)


def _report(bag, tmp_path):
    out = _analyze(bag, tmp_path)
    assert out.returncode == 0, out.stderr
    report = json.loads(out.stdout)["bags"][0]
    md = (tmp_path / "report" / "report.md").read_text()
    return report, md


def test_a_non_finite_sample_is_named_and_left_out(tmp_path, clean_report):
    def alter(topic, data, i, total):
        if topic == "/oscillator/pi2" and i == total - 1:
            return topic, _joint_state_velocity_set(data, float("inf"))
        return topic, data

    report, md = _report(_rewrite_messages(tmp_path / "inf", alter), tmp_path)
    assert any("1 Pi2 samples with a non-finite state" in p for p in report["problems"])
    assert "cannot use" in md and "non-finite" in md
    clean = clean_report["bags"][0]["scenes"][0]
    scene = report["scenes"][0]
    assert scene["samples"] == clean["samples"] - 1
    assert scene["final_vs_exact_orbit"] < 1e-12
    assert scene["samples_to_converge"] == clean["samples_to_converge"]
    assert scene["measured_contraction"]["rho"] == \
        pytest.approx(clean["measured_contraction"]["rho"], rel=1e-2)


def test_corrections_that_are_not_numbers_are_named(tmp_path):
    def alter(topic, data, i, total):
        if topic == "/controller/velocity_correction":
            b = bytearray(data)
            struct.pack_into("<d", b, len(b) - 48, float("nan"))     # twist.linear.x
            return topic, bytes(b)
        return topic, data

    report, md = _report(_rewrite_messages(tmp_path / "nan", alter), tmp_path)
    assert any("1300 of 1300 corrections are not finite" in p for p in report["problems"])
    assert "not finite" in md


def test_swapped_section_topics_are_named(tmp_path):
    swap = {"/oscillator/pi1": "/oscillator/pi2", "/oscillator/pi2": "/oscillator/pi1"}

    def alter(topic, data, i, total):
        return swap.get(topic, topic), data

    report, md = _report(_rewrite_messages(tmp_path / "swapped", alter), tmp_path)
    assert any("pi1 and pi2 topics swapped" in p for p in report["problems"]), report["problems"]
    assert "swapped" in md


def test_the_unaltered_bag_has_no_problem(clean_report):
    assert clean_report["bags"][0]["problems"] == []


def test_a_file_still_being_written_is_not_called_killed(tmp_path):
    from grazing_control.recordings import reader
    data = SOURCE.read_bytes()
    path = tmp_path / "live.mcap"
    path.write_bytes(data[: len(data) // 2])
    raw = reader.read_raw(path)
    assert "still being written?" in raw.problems[0]
    old = reader.WRITING_AGE + 5.0
    st = path.stat()
    os.utime(path, (st.st_atime - old, st.st_mtime - old))
    assert "recorder killed?" in reader.read_raw(path).problems[0]


def test_control_switched_off_by_enable_is_a_named_problem(tmp_path):
    """A third party's `~/enable false` (recorded on /controller/enabled) ends the designed
    control: the report says so (issue 21 §3: the analysis did not notice)."""
    with open(SOURCE, "rb") as fh:
        messages = list(make_reader(fh).iter_messages())
    folder = tmp_path / "enabled"
    with BagWriter(folder, compression="zstd") as w:
        switched = False
        for i, (schema, channel, msg) in enumerate(messages):
            if not w.has_topic(channel.topic):
                w.add_topic(channel.topic, schema.name)
            w.write(channel.topic, msg.data, msg.log_time)
            if not switched and i > len(messages) * 0.9:
                w.add_topic("/controller/enabled", "std_msgs/msg/Bool")
                w.write("/controller/enabled", b"\x00\x01\x00\x00\x00", msg.log_time)
                switched = True
    report, md = _report(folder, tmp_path)
    assert any("~/enable switched the control off" in p for p in report["problems"])
    assert "switched the control off" in md
