"""`grazing replay` of a stream scene (recordings/stream_replay.py): the recorded sensor
stream through a real controller_node.

Lockstep stream scenes recorded here through the nodes (Fast DDS, a domain each): a
1-DOF scene (the model estimator, T/200) and the two-mass chain's scene of
docs/ndof_scene.md (gains from ``grazing design --model ... --mu -0.22``, a
position-only sensor of x0, the model filter), each with a message per sample and in
blocks. Their replay with the recorded parameters gives every answer and every estimate
again, bytes for bytes; another gain gives the difference report; a bag without its
stream is refused in one line before anything starts. :func:`schedule` (where the
replay waits for each answer) is checked on its own.
"""

import time

import pytest

pytest.importorskip("rclpy")

from grazing_control import cli                                        # noqa: E402
from grazing_control.oscillator.params import OscillatorParams         # noqa: E402
from grazing_control.recordings import reader                         # noqa: E402
from grazing_control.recordings.replay import format_result, replay_controller  # noqa: E402
from grazing_control.recordings.scenes import load                     # noqa: E402
from grazing_control.recordings.stream_replay import recorded_lag, schedule  # noqa: E402
from grazing_control.ros import launcher                              # noqa: E402
from grazing_control.ros.stream_block import MESSAGES                 # noqa: E402
from test_closed_loop import new_domain                                # noqa: E402
from test_ndof_nodes import CHAIN                                      # noqa: E402

P = OscillatorParams(delta_d=-5e-6)
PERIODS, ON = 16, 5                     # 1-DOF: control from sample 5
NDOF_PERIODS, NDOF_ON = 12, 4
NDOF_DD = -1e-3
#: The replay's wait for each answer (wall s; `grazing replay`'s default is 2 s): every
#: replay here compares answers, and a controller of a loaded suite stalled past 2 s
#: once (a fresh clone: "17 answers awaited, 1 not in time", then one missing and the
#: count of differing answers off by one). A controller that answers costs no wait.
ANSWER_TIMEOUT = 30.0


@pytest.fixture(scope="module")
def bags(tmp_path_factory):
    """{(scene, stream_message): bag} for scene "1dof" and "ndof" (module docstring)."""
    tmp = tmp_path_factory.mktemp("stream_replay")
    gains = tmp / "g.yaml"
    assert cli.main(["design", "--model", str(CHAIN), "--mu", "-0.22", "--delta-d",
                     str(NDOF_DD), "--out", str(gains)]) == 0
    out = {}
    for mode in MESSAGES:
        sensor = {"state_period": P.period / 200, "sensor_noise": 1e-4,
                  "sensor_velocity": False, "sensor_seed": 7, "stream_message": mode}
        bag = tmp / f"1dof_{mode}"
        res = launcher.run(None, None, bag, PERIODS, delta_d=P.delta_d, enable_after=ON,
                           mode="lockstep", domain_id=new_domain(), timeout=120,
                           sim_overrides=sensor, log_dir=tmp / f"1dof_{mode}_logs",
                           controller_overrides={"pi2_source": "stream",
                                                 "estimator": "model"})
        assert res.ok, res
        out["1dof", mode] = bag
        bag = tmp / f"ndof_{mode}"
        res = launcher.run(None, gains, bag, NDOF_PERIODS, delta_d=NDOF_DD,
                           enable_after=NDOF_ON, mode="lockstep", domain_id=new_domain(),
                           timeout=120, log_dir=tmp / f"ndof_{mode}_logs",
                           sim_overrides={**sensor, "state_period": 4 * 3.141592653589793
                                          / 200},
                           controller_overrides={"pi2_source": "stream",
                                                 "estimator": "model",
                                                 "sensor_coordinate": 0})
        assert res.ok, res
        out["ndof", mode] = bag
    return out


def _stream_topic(mode: str) -> str:
    return "/oscillator/state" if mode == "sample" else "/oscillator/state_block"


@pytest.mark.parametrize("mode", MESSAGES)
@pytest.mark.parametrize("scene", ["1dof", "ndof"])
def test_a_stream_scene_is_replayed_bit_for_bit(bags, tmp_path, scene, mode):
    """Every recorded answer (correction and predicted next one) and estimate again,
    bytes for bytes, the section after the last Pi2 sample's too; the stream published
    as recorded (every message, nothing malformed)."""
    bag = bags[scene, mode]
    res = replay_controller(bag, tmp_path / "out", domain_id=new_domain(),
                            answer_timeout=ANSWER_TIMEOUT)
    cmp_ = res["comparison"]
    n = PERIODS if scene == "1dof" else NDOF_PERIODS
    assert cmp_["all_bit_identical"] and cmp_["bit_identical"] == n, cmp_
    assert res["answers_bytes"]["bit_identical"] == res["answers_bytes"]["recorded"] == n + 1
    assert res["estimates"]["bit_identical"] == res["estimates"]["recorded"] == n + 1
    assert res["stream"]["answers_not_in_time"] == 0
    raw = reader.read_raw(bag)
    topic = _stream_topic(mode)
    assert res["samples_published"] == raw.count(topic) > 0
    # the replay's bag holds what was published, byte for byte, in the recorded order
    new = reader.read_raw(tmp_path / "out")
    assert reader.serialized(new, topic)["data"] == reader.serialized(raw, topic)["data"]
    log = (tmp_path / "out_controller.log").read_text()
    assert f"answered={n + 1} " in log and "malformed=0" in log
    assert "BIT-IDENTICAL" in format_result({"controller": res})


def test_another_gain_gives_the_difference_report(bags, tmp_path, capsys):
    """The 1-DOF scene with c2 = -0.5 (a parameter file of gains only: the recorded
    stream controller's estimator and sensor are kept): the answers before the
    switch-on are the recorded ones, those after it differ, in the Pi2 replay's table."""
    gains = tmp_path / "c05.yaml"
    assert cli.main(["design", "--delta-d", str(P.delta_d), "--c2", "-0.5",
                     "--out", str(gains)]) == 0
    capsys.readouterr()
    code = cli.main(["replay", str(bags["1dof", "sample"]), "--bag", str(tmp_path / "out"),
                     "--controller-params", str(gains), "--no-sim",
                     "--domain-id", str(new_domain()),
                     "--answer-timeout", str(ANSWER_TIMEOUT)])
    text = capsys.readouterr().out
    assert code == 0, text
    assert f"{PERIODS - ON} of {PERIODS} answers differ" in text, text
    assert f"| before the original switch-on | {ON} |" in text
    assert "values over the recorded stream controller's parameters" in text
    assert "-0.5" in text                          # the new gains named


def test_another_n_dof_gain_vector_differs(bags, tmp_path):
    """The two-mass scene with its gain vector scaled by 1.1: the answers from the
    switch-on differ, those before it are the recorded ones."""
    import yaml

    rec = load(bags["ndof", "sample"]).parameters["nodes"]["controller_node"][0]
    gains = tmp_path / "g11.yaml"
    gains.write_text(yaml.safe_dump({"/**": {"ros__parameters": {
        "model_file": rec["model_file"], "gains": [1.1 * g for g in rec["gains"]]}}}))
    res = replay_controller(bags["ndof", "sample"], tmp_path / "out", domain_id=new_domain(),
                            controller_params=gains, answer_timeout=ANSWER_TIMEOUT)
    cmp_ = res["comparison"]
    assert cmp_["differing"] == NDOF_PERIODS - NDOF_ON, cmp_
    assert cmp_["first_differing_sample"] == NDOF_ON
    assert cmp_["new_gains"]["gains"] == [1.1 * g for g in rec["gains"]]


def test_impacts_and_substituted_corrections_are_replayed_where_they_came(tmp_path):
    """A lockstep 1-DOF scene whose controller takes the impacts from oscillator/impact
    (impact_source topic) and whose simulator loses a fifth of the answers (loss 0.2:
    the prediction acts instead, on oscillator/substituted, which the model filter
    integrates): interleaved with the stream as recorded, every answer again; without
    the substitutions (a copy of the bag lacking them) the answers differ after the
    first loss; with the impacts and substitutions logged late (a copy: a recorder behind
    the stream) every answer again."""
    bag = tmp_path / "bag"
    res = launcher.run(None, None, bag, PERIODS, delta_d=P.delta_d, enable_after=ON,
                       mode="lockstep", domain_id=new_domain(), timeout=120,
                       sim_overrides={"state_period": P.period / 200, "loss": 0.2,
                                      "seed": 3},
                       controller_overrides={"pi2_source": "stream",
                                             "impact_source": "topic"},
                       log_dir=tmp_path / "logs")
    assert res.ok, res
    raw = reader.read_raw(bag)
    assert raw.count("/oscillator/substituted") > 0 and raw.count("/oscillator/impact") > 0
    out = replay_controller(bag, tmp_path / "out", domain_id=new_domain(),
                            answer_timeout=ANSWER_TIMEOUT)
    sent = out["stream"]["published"]
    assert sent["substituted"] == raw.count("/oscillator/substituted")
    assert sent["impact"] == raw.count("/oscillator/impact")
    assert out["comparison"]["all_bit_identical"], out["comparison"]
    assert out["answers_bytes"]["differing"] == out["estimates"]["differing"] == 0
    # logged a quarter of the scene late, after the stream that followed them: the
    # replay goes by the stamps, not by the recorder's order
    logs = reader.serialized(reader.read_raw(bag, ["/oscillator/state"]),
                             "/oscillator/state")["log_time"]
    late = _logged_late(bag, tmp_path / "late", {"/oscillator/impact", "/oscillator/substituted"},
                        int(logs.max() - logs.min()) // 4)
    out = replay_controller(late, tmp_path / "out_late", domain_id=new_domain(),
                            answer_timeout=ANSWER_TIMEOUT)
    assert out["comparison"]["all_bit_identical"], out["comparison"]
    lacking = _without(bag, tmp_path / "lacking", "/oscillator/substituted")
    out = replay_controller(lacking, tmp_path / "out2", domain_id=new_domain(),
                            answer_timeout=ANSWER_TIMEOUT)
    assert "/oscillator/substituted not recorded: replayed as if none came" in out["notes"]
    assert out["comparison"]["differing"] > 0


def _without(bag, out, drop: str):
    """A copy of ``bag`` without the topic ``drop`` (every other message as recorded)."""
    return _copy(bag, out, lambda topic, t: None if topic == drop else t)


def _logged_late(bag, out, topics, by: int):
    """A copy of ``bag`` whose ``topics`` were logged ``by`` ns later (a recorder that
    took them after the stream that followed them)."""
    return _copy(bag, out, lambda topic, t: t + by if topic in topics else t)


def _copy(bag, out, log_time):
    """A copy of ``bag``, each message logged at ``log_time(topic, t)`` (None: left out;
    a topic left out entirely is not written)."""
    from grazing_control.ros.recording import BagWriter

    raw = reader.read_raw(bag)
    with BagWriter(out) as writer:
        for topic, ch in raw.channels.items():
            cols = reader.serialized(raw, topic)
            kept = [(log_time(topic, t), data)
                    for t, data in zip(cols["log_time"].tolist(), cols["data"])]
            kept = [(t, data) for t, data in kept if t is not None]
            if not kept and cols["data"]:
                continue
            writer.add_topic(topic, ch.type, ch.metadata.get("offered_qos_profiles", ""))
            for t, data in kept:
                writer.write(topic, data, t)
    return out


@pytest.mark.parametrize("mode", MESSAGES)
def test_a_bag_without_its_stream_is_refused_in_one_line_at_once(bags, tmp_path, capsys,
                                                                  mode):
    topic = _stream_topic(mode)
    bag = _without(bags["1dof", mode], tmp_path / "bag", topic)
    start = time.monotonic()
    code = cli.main(["replay", str(bag), "--bag", str(tmp_path / "out")])
    took = time.monotonic() - start
    err = capsys.readouterr().err
    assert code == 2 and err.startswith("grazing: error:") and err.count("\n") == 1, err
    assert topic in err and "did not record" in err and "--no-controller" in err
    assert took < 10.0 and not (tmp_path / "out").exists()


def test_schedule_is_the_simulators_order_rebuilt_from_the_stamps():
    """The answer of section 10 is awaited after every message stamped up to 10 (the
    stream, an impact, a Pi2 sample: whenever the recorder logged them, before or after
    the answer), and before what acted there instead (a substitution stamped 10); a
    stream message logged before the answer goes before it whatever its stamp (the
    first sample after the section, which the controller needed to answer; stamped 11
    here); an impact the recorder logged after later stream samples goes at its stamp;
    an answer recorded twice is awaited once; equal stamps keep their log order."""
    import struct

    def stamped(stamp):       # a stamped message's bytes as far as its stamp
        return b"\0\1\0\0" + struct.pack("<iI", 0, stamp)

    items = [(10, "state", stamped(4)), (30, "impact", stamped(6)), (30, "state", stamped(8)),
             (40, "state", stamped(10)), (45, "state", stamped(11)),
             (60, "impact", stamped(12)), (70, "state", stamped(14)),
             (20, "pi2", stamped(10)), (80, "substituted", stamped(10)),
             (90, "impact", stamped(9)), (100, "state", stamped(16)),
             (110, "impact", stamped(16))]
    steps = schedule(items, [(50, 10), (120, 20), (120, 20)], "state")
    got = [("answer", s[1]) if s[0] == "answer" else (s[1], struct.unpack_from("<I", s[2], 8)[0])
           for s in steps]
    assert got == [("state", 4), ("impact", 6), ("state", 8), ("impact", 9), ("pi2", 10),
                   ("state", 10), ("state", 11), ("answer", 10), ("substituted", 10),
                   ("impact", 12), ("state", 14), ("state", 16), ("impact", 16),
                   ("answer", 20)]


@pytest.mark.realtime
def test_a_realtime_stream_scene_is_replayed_as_fast_as_the_controller_answers(tmp_path):
    """Realtime at time_scale 100 (a 1-DOF scene at T/200): the controller's answers
    depend on the samples' stamps, not on when they came, so the replay, as fast as the
    controller answers, gives them again bit for bit, while the recorded controller read
    every recorded sample (it answered at most its subscription's 1000 messages behind
    the stream); where it fell further behind it lost samples the recorder kept, and
    the report says so."""
    bag = tmp_path / "rt"
    res = launcher.run(None, None, bag, PERIODS, delta_d=P.delta_d, enable_after=ON,
                       mode="realtime", domain_id=new_domain(), timeout=120,
                       sim_overrides={"state_period": P.period / 200, "time_scale": 100.0,
                                      "watchdog_misses": 0, "watchdog_pace": 0.0,
                                      "watchdog_lag": 0.0, "watchdog_excursion": 0.0},
                       controller_overrides={"pi2_source": "stream"},
                       log_dir=tmp_path / "logs")
    assert res.ok, res
    out = replay_controller(bag, tmp_path / "out", domain_id=new_domain(),
                            answer_timeout=ANSWER_TIMEOUT)
    assert any("a realtime scene" in n for n in out["notes"])
    if out["stream"]["recorded_lag_messages"] <= 1000:
        assert out["comparison"]["all_bit_identical"], out["comparison"]
        assert out["answers_bytes"]["differing"] == out["estimates"]["differing"] == 0
    else:
        assert "lost samples the recorder kept" in out.get("why", ""), out


def test_the_recorded_lag_counts_the_stream_messages_before_a_late_answer():
    """Answer 10 logged after the stream messages stamped 12 and 14 (two behind), answer
    20 logged right after its section's last message (none behind)."""
    import struct

    def state(stamp):
        return b"\0\1\0\0" + struct.pack("<iI", 0, stamp)

    items = [(1, "state", state(8)), (2, "state", state(10)), (3, "state", state(12)),
             (4, "state", state(14)), (5, "impact", state(13)), (7, "state", state(20)),
             (9, "state", state(22))]
    assert recorded_lag(items, [(6, 10), (8, 20)], "state") == (2, 10)
    assert recorded_lag(items, [(8, 20)], "state") == (0, None)       # never behind


def test_a_rig_scenes_bag_is_sent_to_replay_rig():
    from types import SimpleNamespace

    from grazing_control.recordings.stream_replay import check

    data = SimpleNamespace(path="bag", present={}, topics={})
    with pytest.raises(ValueError, match="replay it with grazing replay-rig"):
        check(data, {"pi2_source": "stream", "rig_file": "rig.yaml"}, [])
