"""Behavioural tests of recorder_node over real middleware (Fast DDS).

The recorder runs as a separate process (``python -m
grazing_control.ros.recorder_node``), isolated from concurrent tests by its
own ``ROS_DOMAIN_ID`` and namespace; this test process publishes on every
recorded topic with reliable QoS, waits until the recorder has acknowledged
every message, then stops it with a signal. The bag must then hold every
message, in order and equal, for both bag readers.
"""

import itertools
import os
import resource
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import rclpy
from builtin_interfaces.msg import Time
from geometry_msgs.msg import TwistStamped, Vector3Stamped
from rclpy.context import Context
from rclpy.duration import Duration
from rclpy.executors import SingleThreadedExecutor
from rclpy.qos import (DurabilityPolicy, HistoryPolicy, QoSCompatibility, QoSProfile,
                       ReliabilityPolicy, qos_check_compatible)
from std_msgs.msg import Bool
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import JointState

from grazing_control.ros.common import LATCHED_QOS, READY_TOPIC
from grazing_control.ros.recording.topics import DEFAULT_TOPICS, adapted_qos, parse_topics
from test_closed_loop import new_domain
from grazing_control.oscillator.params import ParameterError
from grazing_control.ros.recording import (message_to_dict, read_messages,
                                           read_messages_rosbags, read_metadata)

REPO = Path(__file__).resolve().parents[1]
N = 150                      # messages per topic
STARTUP_TIMEOUT = 20.0

_CLASSES = {
    "sensor_msgs/msg/JointState": JointState,
    "geometry_msgs/msg/Vector3Stamped": Vector3Stamped,
    "geometry_msgs/msg/TwistStamped": TwistStamped,
    "rosgraph_msgs/msg/Clock": Clock,
}
_ids = itertools.count()


def make_message(msg_type, i):
    stamp = Time(sec=i, nanosec=7 * i)
    if msg_type == "rosgraph_msgs/msg/Clock":
        return Clock(clock=stamp)
    msg = _CLASSES[msg_type]()
    msg.header.stamp = stamp
    if msg_type == "sensor_msgs/msg/JointState":
        msg.name, msg.position, msg.velocity, msg.effort = ["mass"], [i * 1e-3], [-i / 7], [0.5]
    elif msg_type == "geometry_msgs/msg/Vector3Stamped":
        msg.vector.x, msg.vector.y, msg.vector.z = -0.1 * i, 0.08 * i, 1.0
    else:
        msg.twist.linear.x = i * 1e-6
    return msg


@pytest.fixture
def isolation():
    """A domain id and a namespace that no concurrent test uses."""
    uid = f"{os.getpid()}_{next(_ids)}"
    domain = new_domain()
    env = dict(os.environ, ROS_DOMAIN_ID=str(domain),
               ROS_AUTOMATIC_DISCOVERY_RANGE="LOCALHOST",
               PYTHONPATH=os.pathsep.join([str(REPO), os.environ.get("PYTHONPATH", "")]),
               PYTHONUNBUFFERED="1")
    return domain, f"/rec_test_{uid}", env


def start_recorder(bag, namespace, env, *params):
    args = [sys.executable, "-m", "grazing_control.ros.recorder_node", "--ros-args",
            "-r", f"__ns:={namespace}", "-p", f"output:={bag}"]
    for p in params:
        args += ["-p", p]
    return subprocess.Popen(args, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            text=True)


@pytest.fixture
def ros(isolation):
    """A node of this test process in the isolated domain and namespace."""
    domain, namespace, _ = isolation
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("test_publisher", namespace=namespace, context=context)
    yield node
    node.destroy_node()
    rclpy.try_shutdown(context=context)


def publish_all(node, recorder, n, topics=tuple(DEFAULT_TOPICS), matches=None):
    """Publish `n` messages on each of `topics` once the recorder matches.

    ``matches`` gives, per topic name, how many subscriptions to wait for (default 1;
    with use_sim_time the recorder's time source subscribes to /clock as well).
    Returns {fully qualified topic: [messages]}.
    """
    matches = matches or {}
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=n,
                     reliability=ReliabilityPolicy.RELIABLE)
    pubs = {}
    for name in topics:
        msg_type = DEFAULT_TOPICS[name]
        pub = node.create_publisher(_CLASSES[msg_type], name, qos)
        pubs[pub.topic_name] = (pub, msg_type, matches.get(name, 1))
    deadline = time.monotonic() + STARTUP_TIMEOUT
    while any(p.get_subscription_count() < k for p, _, k in pubs.values()):
        assert recorder.poll() is None, recorder.communicate()[0]
        assert time.monotonic() < deadline, "recorder did not subscribe"
        time.sleep(0.05)
    sent = {topic: [] for topic in pubs}
    for i in range(n):
        for topic, (pub, msg_type, _k) in pubs.items():
            msg = make_message(msg_type, i)
            pub.publish(msg)
            sent[topic].append(msg)
    for pub, _, _k in pubs.values():
        assert pub.wait_for_all_acked(Duration(seconds=10))
    return sent


def _size(path) -> int:
    """The file's size, 0 while it does not exist."""
    try:
        return path.stat().st_size
    except FileNotFoundError:
        return 0


def stop(recorder, signum):
    recorder.send_signal(signum)
    try:
        output, _ = recorder.communicate(timeout=15)
    except subprocess.TimeoutExpired:
        recorder.kill()
        raise
    return recorder.returncode, output


def assert_bag_holds(bag, sent):
    for read in (read_messages, read_messages_rosbags):
        got = {topic: [] for topic in sent}
        last_time = {}
        for m in read(bag):
            got[m.topic].append(message_to_dict(m.message))
            assert m.log_time_ns >= last_time.get(m.topic, 0)
            last_time[m.topic] = m.log_time_ns
        for topic, msgs in sent.items():
            assert got[topic] == [message_to_dict(x) for x in msgs], (read.__name__, topic)
    info = read_metadata(bag)
    assert info["message_count"] == sum(len(v) for v in sent.values())
    for entry in info["topics_with_message_count"]:
        meta = entry["topic_metadata"]
        if meta["name"] not in sent and entry["message_count"] == 0:
            continue        # recorded by default (the parameter record), nothing published
        assert entry["message_count"] == len(sent[meta["name"]])
        assert meta["offered_qos_profiles"][0]["reliability"] == "reliable"


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_records_every_message_and_closes_on_signal(tmp_path, isolation, ros, signum):
    _, namespace, env = isolation
    bag = tmp_path / "run"
    recorder = start_recorder(bag, namespace, env)
    try:
        sent = publish_all(ros, recorder, N)
    finally:
        rc, output = stop(recorder, signum)
    assert rc == 0, output
    assert "Traceback" not in output
    assert f"closed {bag}/run_0.mcap: {len(DEFAULT_TOPICS) * N} messages" in output
    assert set(sent) == {ros.resolve_topic_name(t) for t in DEFAULT_TOPICS}
    assert_bag_holds(bag, sent)


def test_selected_topics_and_lz4(tmp_path, isolation, ros):
    _, namespace, env = isolation
    bag = tmp_path / "sel"
    recorder = start_recorder(bag, namespace, env, "compression:=lz4",
                              "topics:=['oscillator/pi2', '/clock']")
    try:
        sent = publish_all(ros, recorder, 20, topics=["oscillator/pi2", "/clock"])
    finally:
        rc, output = stop(recorder, signal.SIGTERM)
    assert rc == 0, output
    assert set(sent) == {f"{namespace}/oscillator/pi2", "/clock"}
    assert_bag_holds(bag, sent)


@pytest.mark.parametrize("params, reason", [
    ([], "output='' is invalid"),
    (["compression:=gzip"], "compression='gzip' is invalid"),
    (["topics:=['oscillator/nothing']"], "topics entry 'oscillator/nothing' is invalid"),
    (["topics:=[]"], "topics=[] is invalid"),
    (["topics:=a_string"], "topics=a_string is invalid: expected type STRING_ARRAY"),
    (["chunk_size:=abc"], "chunk_size=abc is invalid: expected type INTEGER"),
    # the described range refuses them (ros2 param describe: Min 0.0, Max 0.1)
    (["batch_window:=-0.001"], "batch_window=-0.001 is invalid: Parameter batch_window out "
                               "of range Min: 0.0, Max: 0.1"),
    (["batch_window:=5.0"], "batch_window=5.0 is invalid: Parameter batch_window out of "
                            "range Min: 0.0, Max: 0.1"),
    (["output:=123"], "output=123 is invalid: expected type STRING"),
    (["outptu:=x"], "unknown parameter outptu"),
])
def test_bad_parameters_exit_nonzero_without_traceback(tmp_path, isolation, params, reason):
    _, namespace, env = isolation
    args = [sys.executable, "-m", "grazing_control.ros.recorder_node", "--ros-args"]
    if params != []:
        args += ["-p", f"output:={tmp_path / 'bag'}"]
    for p in params:
        args += ["-p", p]
    done = subprocess.run(args, env=env, capture_output=True, text=True, timeout=30)
    output = done.stdout + done.stderr
    assert done.returncode == 2, output
    assert reason in output and len(output.strip().splitlines()) == 1, output
    assert "Traceback" not in output
    assert not (tmp_path / "bag").exists()


def test_existing_bag_is_not_overwritten(tmp_path, isolation):
    _, namespace, env = isolation
    (tmp_path / "bag").mkdir()
    (tmp_path / "bag" / "metadata.yaml").write_text("keep me")
    done = subprocess.run(
        [sys.executable, "-m", "grazing_control.ros.recorder_node", "--ros-args",
         "-p", f"output:={tmp_path / 'bag'}"],
        env=env, capture_output=True, text=True, timeout=30)
    assert done.returncode == 2
    assert "not empty" in done.stdout + done.stderr
    assert "Traceback" not in done.stdout + done.stderr
    assert (tmp_path / "bag" / "metadata.yaml").read_text() == "keep me"


def test_parse_topics():
    assert parse_topics(["oscillator/state", "/clock"]) == {
        "oscillator/state": "sensor_msgs/msg/JointState", "/clock": "rosgraph_msgs/msg/Clock"}
    assert parse_topics(["/oscillator/pi1"]) == {"oscillator/pi1": "sensor_msgs/msg/JointState"}
    assert parse_topics(["chatter std_msgs/msg/String"]) == {"chatter": "std_msgs/msg/String"}
    with pytest.raises(ParameterError):
        parse_topics([])
    with pytest.raises(ParameterError):
        parse_topics(["a b c"])


def test_use_sim_time_stamps_log_time_with_clock(tmp_path, isolation, ros):
    _, namespace, env = isolation
    bag = tmp_path / "sim"
    recorder = start_recorder(bag, namespace, env, "use_sim_time:=true",
                              "topics:=['oscillator/state', '/clock']")
    try:
        # the recorder and its use_sim_time time source both subscribe to /clock
        sent = publish_all(ros, recorder, 30, topics=["/clock", "oscillator/state"],
                           matches={"/clock": 2})
    finally:
        rc, output = stop(recorder, signal.SIGTERM)
    assert rc == 0, output
    assert_bag_holds(bag, sent)
    assert read_metadata(bag)["custom_data"] == {"log_time": "ros_clock", "recorder_status": "0",
                                                 "recorder_received": "60"}
    clock_ns = {0} | {m.clock.sec * 10**9 + m.clock.nanosec for m in sent["/clock"]}
    assert {m.log_time_ns for m in read_messages(bag)} <= clock_ns


# ------------------------------------------------------------------ QoS, completeness
BEST_EFFORT = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                         reliability=ReliabilityPolicy.BEST_EFFORT)
LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                     reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


def wait_ready(node, recorder, *matched):
    """Wait until the recorder says (on recorder/ready) that it matched every topic, and
    until each publisher of ``matched`` has matched a reader (the recorder's)."""
    ready = []
    sub = node.create_subscription(Bool, READY_TOPIC, lambda m: ready.append(m.data),
                                   LATCHED_QOS)
    executor = SingleThreadedExecutor(context=node.context)
    executor.add_node(node)
    deadline = time.monotonic() + STARTUP_TIMEOUT
    while not (ready and ready[-1]):
        assert recorder.poll() is None, recorder.communicate()[0]
        assert time.monotonic() < deadline, "recorder not ready"
        executor.spin_once(timeout_sec=0.05)
    executor.remove_node(node)
    node.destroy_subscription(sub)
    # "ready" says the recorder matched this node's publishers; a message is delivered
    # only once the publisher has matched the recorder's reader too (the other end of the
    # match, under load later): wait for that end as well (a burst published at once lost
    # its first messages: the disk-full test read a bag that did not start at 0, a rerun)
    # Only the pairs whose QoS can match: a best-effort bystander beside the recorder's
    # reliable reader never matches, and waited out the 5 s below as the normal path.
    end = time.monotonic() + 5.0
    while time.monotonic() < end and not all(
            pub.get_subscription_count() >= sum(
                info.node_name != node.get_name() and qos_check_compatible(
                    pub.qos_profile, info.qos_profile)[0] != QoSCompatibility.ERROR
                for info in node.get_subscriptions_info_by_topic(pub.topic_name))
            for pub in node.publishers):
        time.sleep(0.02)
    # That count is of the readers this node's graph already knows: where it had not yet
    # discovered the recorder's reader it asked for none, and a burst published at once
    # went to nobody (the disk-full test's bag began at message 1631, a fresh clone's
    # rerun, 2026-11-29). The publishers a test bursts on wait for a reader of their own.
    end = time.monotonic() + STARTUP_TIMEOUT
    while not all(pub.get_subscription_count() >= 1 for pub in matched):
        assert time.monotonic() < end, "the recorder's reader never matched"
        time.sleep(0.01)


def test_adapts_to_best_effort_and_transient_local_publishers(tmp_path, isolation, ros):
    """As ros2 bag record, on topics that are not the package's: a best-effort publisher
    is recorded, and a transient-local one's messages from before the recorder started
    are too."""
    _, namespace, env = isolation
    be = ros.create_publisher(JointState, "rig/pi2", BEST_EFFORT)
    latched = ros.create_publisher(JointState, "rig/pi1", LATCHED)
    early = [make_message("sensor_msgs/msg/JointState", i) for i in range(5)]
    for m in early:
        latched.publish(m)                       # nobody listens yet
    bag = tmp_path / "qos"
    recorder = start_recorder(bag, namespace, env,
                              "topics:=['rig/pi2 sensor_msgs/msg/JointState', "
                              "'rig/pi1 sensor_msgs/msg/JointState']")
    try:
        wait_ready(ros, recorder)
        time.sleep(0.3)                          # both ends of the best-effort match
        late = [make_message("sensor_msgs/msg/JointState", i) for i in range(5, 25)]
        for m in late:
            be.publish(m)
            latched.publish(m)
            time.sleep(0.002)                    # best effort: no flood
        assert latched.wait_for_all_acked(Duration(seconds=10))
        time.sleep(0.5)
    finally:
        rc, output = stop(recorder, signal.SIGTERM)
    assert rc == 0, output
    got = {}
    for m in read_messages(bag):
        got.setdefault(m.topic, []).append(message_to_dict(m.message))
    assert got[f"{namespace}/rig/pi2"] == [message_to_dict(m) for m in late]
    assert got[f"{namespace}/rig/pi1"] == [message_to_dict(m) for m in early + late]
    qos = {e["topic_metadata"]["name"]: e["topic_metadata"]["offered_qos_profiles"][0]
           for e in read_metadata(bag)["topics_with_message_count"]}
    assert qos[f"{namespace}/rig/pi2"]["reliability"] == "best_effort"
    assert qos[f"{namespace}/rig/pi1"]["durability"] == "transient_local"


@pytest.mark.parametrize("bystander_first", [True, False], ids=["bystander first",
                                                                "package first"])
def test_a_best_effort_bystander_does_not_make_the_package_topics_lossy(
        tmp_path, isolation, ros, bystander_first):
    """A passive best-effort publisher on the package's own topics (before or after the
    package's reliable one): the recording stays reliable, every message of a fast burst
    is recorded, the bystander is named in a warning, and losses are still counted."""
    _, namespace, env = isolation
    reliable = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=3000,
                          reliability=ReliabilityPolicy.RELIABLE)
    topics = ("oscillator/state", "/clock")

    def bystanders():
        return [ros.create_publisher(_CLASSES[DEFAULT_TOPICS[t]], t, BEST_EFFORT)
                for t in topics]

    def package():
        return {t: ros.create_publisher(_CLASSES[DEFAULT_TOPICS[t]], t, reliable)
                for t in topics}

    bag = tmp_path / "bystander"
    args = ("require_complete:=true", "topics:=['oscillator/state', '/clock']")
    if bystander_first:
        others = bystanders()
        recorder = start_recorder(bag, namespace, env, *args)
    else:
        pubs = package()
        # published before the recorder exists: missed, and counted as missed although a
        # (silent) second publisher joins the topic
        pubs["oscillator/state"].publish(make_message("sensor_msgs/msg/JointState", 0))
        recorder = start_recorder(bag, namespace, env, *args)
        others = bystanders()
    try:
        if bystander_first:
            time.sleep(1.0)                     # the recorder sees only the bystanders
            pubs = package()
        time.sleep(0.5)
        # the burst goes out on both topics: each writer waits for the recorder's reader
        # (only the state's did, and /clock's first 25 went to nobody: 1975 of 2000, a
        # fresh clone's rerun, 2026-11-30)
        wait_ready(ros, recorder, *pubs.values())
        sent = []
        for i in range(1, 2001):                 # a burst: best effort would drop some
            m = make_message("sensor_msgs/msg/JointState", i)
            pubs["oscillator/state"].publish(m)
            sent.append(m)
            clock = Clock()
            clock.clock.sec = i
            pubs["/clock"].publish(clock)
        for pub in pubs.values():
            assert pub.wait_for_all_acked(Duration(seconds=20))
    finally:
        rc, output = stop(recorder, signal.SIGTERM)
    assert len(others) == 2
    if bystander_first:
        assert rc == 0 and "missed" not in output, output
    else:
        assert rc == 1 and f"missed: {namespace}/oscillator/state 1" in output, output
    assert "best-effort publisher(s) not recorded" in output
    got = [message_to_dict(m.message) for m in read_messages(bag)
           if m.topic == f"{namespace}/oscillator/state"]
    assert got == [message_to_dict(m) for m in sent]
    assert sum(1 for m in read_messages(bag) if m.topic == "/clock") == 2000
    qos = {e["topic_metadata"]["name"]: e["topic_metadata"]["offered_qos_profiles"]
           for e in read_metadata(bag)["topics_with_message_count"]}
    assert [q["reliability"] for q in qos[f"{namespace}/oscillator/state"]] == ["reliable"]


def test_adapted_qos_follows_rosbag2():
    reliable = QoSProfile(depth=1, reliability=ReliabilityPolicy.RELIABLE)
    qos, warnings = adapted_qos([BEST_EFFORT, reliable])
    assert qos.reliability == ReliabilityPolicy.BEST_EFFORT and len(warnings) == 1
    qos, warnings = adapted_qos([BEST_EFFORT, reliable], own=True)
    assert qos.reliability == ReliabilityPolicy.RELIABLE and "not recorded" in warnings[0]
    qos, warnings = adapted_qos([BEST_EFFORT], own=True)       # only a bystander so far
    assert qos.reliability == ReliabilityPolicy.RELIABLE and len(warnings) == 1
    assert qos.durability == DurabilityPolicy.VOLATILE
    qos, warnings = adapted_qos([LATCHED, LATCHED])
    assert qos.reliability == ReliabilityPolicy.RELIABLE and not warnings
    assert qos.durability == DurabilityPolicy.TRANSIENT_LOCAL
    qos, warnings = adapted_qos([LATCHED, reliable])
    assert qos.durability == DurabilityPolicy.VOLATILE and len(warnings) == 1


def test_reports_what_it_missed(tmp_path, isolation, ros):
    """Messages published before the recorder matched are counted from the publisher's
    sequence numbers; with require_complete the exit status says so."""
    _, namespace, env = isolation
    qos = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=100,
                     reliability=ReliabilityPolicy.RELIABLE)
    pub = ros.create_publisher(JointState, "oscillator/pi2", qos)
    for i in range(7):
        pub.publish(make_message("sensor_msgs/msg/JointState", i))     # lost: no reader
    bag = tmp_path / "missed"
    recorder = start_recorder(bag, namespace, env, "topics:=['oscillator/pi2']",
                              "require_complete:=true")
    try:
        wait_ready(ros, recorder, pub)
        time.sleep(0.3)
        for i in range(7, 12):
            pub.publish(make_message("sensor_msgs/msg/JointState", i))
        assert pub.wait_for_all_acked(Duration(seconds=10))
    finally:
        rc, output = stop(recorder, signal.SIGTERM)
    assert rc == 1, output
    assert f"missed: {namespace}/oscillator/pi2 7 " in output, output
    assert [m.message.position[0] for m in read_messages(bag)] == \
        [i * 1e-3 for i in range(7, 12)]


def _fsize_limit(limit):
    def apply():
        signal.signal(signal.SIGXFSZ, signal.SIG_IGN)    # write() fails with EFBIG instead
        resource.setrlimit(resource.RLIMIT_FSIZE, (limit, limit))
    return apply


def _tmpfs_available():
    return shutil.which("unshare") is not None and subprocess.run(
        ["unshare", "-rm", "sh", "-c", "mount -t tmpfs -o size=64k tmpfs /mnt"],
        capture_output=True).returncode == 0


@pytest.mark.parametrize("how", ["file_size_limit", "full_tmpfs"])
def test_disk_full_is_one_error_line_and_keeps_the_chunks(tmp_path, isolation, ros, how):
    """A write that fails stops the recording with one [ERROR] line and status 2.

    file_size_limit: RLIMIT_FSIZE makes write() fail with EFBIG (the file stays, and is
    still read up to its last complete chunk); full_tmpfs: a 64 kB tmpfs in a private
    mount namespace (unshare) makes it fail with ENOSPC, as a full disk does.
    """
    _, namespace, env = isolation
    args = [sys.executable, "-m", "grazing_control.ros.recorder_node", "--ros-args",
            "-r", f"__ns:={namespace}", "-p", "topics:=['oscillator/state']",
            "-p", "compression:=none", "-p", "chunk_size:=4096"]
    if how == "file_size_limit":
        bag, kw = tmp_path / "full", {"preexec_fn": _fsize_limit(40_000)}
    else:
        if not _tmpfs_available():
            pytest.skip("no user namespaces: cannot mount a small tmpfs")
        mnt = tmp_path / "mnt"
        mnt.mkdir()
        bag, kw = mnt / "full", {}
        args = ["unshare", "-rm", "sh", "-c",
                f'mount -t tmpfs -o size=64k tmpfs {mnt} && exec "$0" "$@"'] + args
    args += ["-p", f"output:={bag}"]
    recorder = subprocess.Popen(args, env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.STDOUT, text=True, **kw)
    try:
        pub = ros.create_publisher(JointState, "oscillator/state", QoSProfile(
            history=HistoryPolicy.KEEP_LAST, depth=5000,
            reliability=ReliabilityPolicy.RELIABLE))
        wait_ready(ros, recorder, pub)
        for i in range(3000):                    # about 300 kB of CDR
            pub.publish(make_message("sensor_msgs/msg/JointState", i))
        output, _ = recorder.communicate(timeout=30)   # it stops by itself
    finally:
        if recorder.poll() is None:
            recorder.kill()
    assert recorder.returncode == 2, output
    errors = [ln for ln in output.splitlines() if "[ERROR]" in ln]
    assert len(errors) == 1 and "Traceback" not in output, output
    reason = "File too large" if how == "file_size_limit" else "No space left on device"
    assert reason in errors[0], errors
    if how == "file_size_limit":
        kept = list(read_messages(bag))
        assert 0 < len(kept) < 3000
        assert [m.message.position[0] for m in kept] == [i * 1e-3 for i in range(len(kept))]


def test_sigkilled_recording_opens_in_every_reader_after_reindex(tmp_path, isolation, ros):
    """A recorder killed with SIGKILL leaves no summary and no metadata.yaml; `grazing
    bag reindex` rewrites both, keeping every message of the complete chunks."""
    from mcap.reader import SeekingReader

    _, namespace, env = isolation
    bag = tmp_path / "killed"
    recorder = start_recorder(bag, namespace, env, "topics:=['oscillator/pi2']",
                              "compression:=none", "chunk_size:=4096")
    try:
        sent = publish_all(ros, recorder, 400, topics=["oscillator/pi2"])
        # acknowledged is received by the recorder's reader, not yet written: the kill
        # waits for complete chunks on disk (a fresh clone once killed it before the
        # recorder had taken any: 0 messages after the reindex)
        deadline = time.monotonic() + 15.0
        while _size(bag / "killed_0.mcap") < 3 * 4096:
            assert time.monotonic() < deadline, "no complete chunk written in 15 s"
            time.sleep(0.05)
    finally:
        recorder.send_signal(signal.SIGKILL)
        recorder.communicate(timeout=15)
    assert recorder.returncode == -signal.SIGKILL
    assert not (bag / "metadata.yaml").exists()
    with open(bag / "killed_0.mcap", "rb") as f, pytest.raises(Exception):
        SeekingReader(f).get_summary().statistics.message_count    # no summary
    done = subprocess.run([sys.executable, "-c", "import sys; from grazing_control.cli "
                           "import main; sys.exit(main())", "bag", "reindex", str(bag)],
                          env=env, capture_output=True, text=True, timeout=60)
    assert done.returncode == 0 and "metadata.yaml written" in done.stdout, done.stderr
    want = [message_to_dict(m) for m in next(iter(sent.values()))]
    with open(bag / "killed_0.mcap", "rb") as f:
        n = SeekingReader(f).get_summary().statistics.message_count
    assert 0 < n <= len(want)
    for read in (read_messages, read_messages_rosbags):       # mcap_ros2, rosbags
        assert [message_to_dict(m.message) for m in read(bag)] == want[:n], read.__name__
    assert read_metadata(bag)["message_count"] == n
    print(f"recovered {n} of {len(want)} messages")


def test_a_simulator_waiting_for_its_recorder_fails_when_the_recorder_dies(tmp_path,
                                                                          monkeypatch):
    """A scene that waits for its recorder (wait_for_recorder, as `grazing run --bag` and a
    launch with a bag) is recorded; when the recorder is SIGKILLed mid-scene the
    simulator, once the recorder has left the graph (DDS liveliness: the participants
    here announce a 2 s lease, tests/fastdds_short_lease.xml; Fast DDS's default is 20 s),
    stops with one error line and status 1 instead of finishing with status 0 and no
    record (issue 19 §4)."""
    from grazing_control.ros import launcher as L

    profile = str(Path(__file__).with_name("fastdds_short_lease.xml"))
    monkeypatch.setenv("FASTRTPS_DEFAULT_PROFILES_FILE", profile)
    monkeypatch.setenv("FASTDDS_DEFAULT_PROFILES_FILE", profile)

    root = Path(__file__).resolve().parents[1]
    domain = new_domain()
    procs = []
    try:
        rec = L.start_node(L.RECORDER_MODULE, [], {"output": str(tmp_path / "bag")},
                           domain_id=domain, log=tmp_path / "rec.log")
        procs.append(rec)
        procs.append(L.start_node(L.CONTROLLER_MODULE, [root / "config" / "controller.yaml"],
                                  {}, domain_id=domain, log=tmp_path / "ctl.log"))
        sim = L.start_node(L.SIM_MODULE, [root / "config" / "study.yaml"],
                           {"max_periods": 10_000_000, "exit_when_done": True,
                            "wait_for_recorder": True, "state_period": 0.0},
                           domain_id=domain, log=tmp_path / "sim.log")
        procs.append(sim)
        deadline = time.monotonic() + 60
        # the scene runs, recorded: the simulator has found its recorder and started (a
        # fixed 2 s after its first line before; under load not always past the start)
        while "start conditions met" not in (tmp_path / "sim.log").read_text():
            assert time.monotonic() < deadline and sim.poll() is None, \
                (tmp_path / "sim.log").read_text()
            time.sleep(0.1)
        assert "summary" not in (tmp_path / "sim.log").read_text()
        rec.kill()
        assert sim.wait(90) == 1
        text = (tmp_path / "sim.log").read_text()
        assert text.count("[ERROR]") == 1 and "the scene's recording is lost" in text, text
        assert "Traceback" not in text and "FATAL" not in text
    finally:
        L.stop_nodes(procs)


@pytest.mark.parametrize("module, params, overrides, text", [
    ("RECORDER_MODULE", [], {"chunk_size": 0}, "chunk_size=0 is invalid: Parameter chunk_size "
     "out of range. Min: 1"),
    ("RECORDER_MODULE", [], {"compression": "bogus"}, "valid values are zstd, lz4, none"),
    ("CONTROLLER_MODULE", ["controller.yaml"], {"saturation": 0.0},
     "saturation=0.0 is invalid: Parameter saturation out of range Min: 5e-324"),
])
def test_descriptors_advertise_what_validation_accepts(tmp_path, module, params, overrides, text):
    """The ranges a node advertises (ros2 param describe) are the ones it enforces:
    saturation > 0 (it advertised [0, inf] and refused 0), chunk_size > 0 (no range),
    compression one of three (only in the description); one line, status 2."""
    from grazing_control.ros import launcher as L

    root = Path(__file__).resolve().parents[1]
    overrides = {"output": str(tmp_path / "bag"), **overrides} if module == "RECORDER_MODULE" \
        else overrides
    proc = L.start_node(getattr(L, module), [root / "config" / p for p in params], overrides,
                        domain_id=new_domain(), log=tmp_path / "node.log")
    try:
        assert proc.wait(60) == 2
    finally:
        L.stop_nodes([proc])
    log = (tmp_path / "node.log").read_text()
    assert text in log and log.count("[ERROR]") == 1 and "Traceback" not in log, log


def _end_of_scene(bag, isolation, ros, close_timeout, extra, announce):
    """A controller's end of scene as a recorder (require_complete, ``close_timeout``)
    sees it: 30 corrections taken, then the recorder is stopped (SIGTERM) while
    ``extra`` more are still to come, then the published record saying ``announce`` were
    published. Returns the recorder's exit status and output, the /diagnostics statuses
    and recorder/complete messages it sent, and the corrections' topic."""
    from diagnostic_msgs.msg import DiagnosticArray
    from std_msgs.msg import String

    from grazing_control.ros.recording import record

    _, namespace, env = isolation
    recorder = start_recorder(
        bag, namespace, env, "require_complete:=true", f"close_timeout:={close_timeout}",
        "topics:=['controller/velocity_correction', 'grazing/parameters', "
        "'grazing/published']")

    corrections = ros.create_publisher(TwistStamped, "controller/velocity_correction",
                                       QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000,
                                                  reliability=ReliabilityPolicy.RELIABLE))
    params = ros.create_publisher(String, record.TOPIC, LATCHED_QOS)
    published = ros.create_publisher(String, record.PUBLISHED_TOPIC, LATCHED_QOS)
    statuses, confirmed = [], []
    ros.create_subscription(DiagnosticArray, "/diagnostics",
                            lambda m: statuses.extend(m.status), 10)
    ros.create_subscription(String, "recorder/complete", lambda m: confirmed.append(m.data),
                            LATCHED_QOS)
    node = f"{namespace}/controller_node"
    params.publish(String(data=record.encode(node, {"c2": -1.0})))
    wait_ready(ros, recorder)
    # the recorder's readiness is its reader having matched this writer; the writer may
    # not have matched the reader yet (discovery runs on each side), and what it
    # published before went to nobody and was acked by nobody (a fresh clone's rerun:
    # the recorder took the 20 late corrections and not the first 30)
    end = time.monotonic() + 10.0
    while corrections.get_subscription_count() == 0 and time.monotonic() < end:
        time.sleep(0.01)
    assert corrections.get_subscription_count() == 1
    for i in range(30):
        corrections.publish(make_message("geometry_msgs/msg/TwistStamped", i))
    assert corrections.wait_for_all_acked(Duration(seconds=10))
    assert params.wait_for_all_acked(Duration(seconds=10))    # it knows the node
    recorder.send_signal(signal.SIGTERM)       # the launcher stopped it here, at once
    time.sleep(1.0)                            # the stopped recorder is still waiting
    for i in range(30, 30 + extra):
        corrections.publish(make_message("geometry_msgs/msg/TwistStamped", i))
    published.publish(String(data=record.encode_published(
        node, {corrections.topic_name: announce})))
    executor = SingleThreadedExecutor(context=ros.context)
    executor.add_node(ros)
    deadline = time.monotonic() + 30
    while recorder.poll() is None and time.monotonic() < deadline:
        executor.spin_once(timeout_sec=0.05)
    # what the recorder published last (recorder/complete, its final status) may still be
    # in this reader's queue when the process is gone: take it
    end = time.monotonic() + 2.0
    while time.monotonic() < end and not confirmed:
        executor.spin_once(timeout_sec=0.05)
    executor.remove_node(ros)
    output, _ = recorder.communicate(timeout=15)
    return recorder.returncode, output, (statuses, confirmed), corrections.topic_name


def test_a_stopped_recorder_waits_for_what_the_nodes_said_they_published(tmp_path,
                                                                          isolation, ros):
    """Issue 27, the mechanism: the recorder was stopped while the last corrections of a
    loaded scene were still on their way, closed with what it had (1412 of 1501) and
    said nothing, since a lost tail leaves no gap in the sequence numbers. Stopped
    while 20 corrections are still to come, it waits for the controller's published
    record and records all 50, then says so on recorder/complete (the controller exits
    on it); its /diagnostics status counts them."""
    bag = tmp_path / "bag"
    rc, output, (statuses, confirmed), topic = _end_of_scene(bag, isolation, ros, 30.0, 20,
                                                             50)
    assert rc == 0, output
    stamps = [m.message.header.stamp.sec for m in read_messages(bag)
              if m.topic.endswith("velocity_correction")]
    assert stamps == list(range(50))
    assert "missed" not in output and "no published record" not in output
    info = read_metadata(bag)["custom_data"]
    assert info["recorder_status"] == "0" and "recorder_missed" not in info
    ours = [s for s in statuses if s.name.endswith("recorder_node: recording")]
    assert ours and "recorder_node" in ours[-1].hardware_id
    values = {kv.key: kv.value for kv in ours[-1].values}
    assert values["dropped"] == "0" and values["missed"] == "0"
    assert int(values["written"]) == int(values["received"]) >= 30
    namespace = topic[:-len("/controller/velocity_correction")]
    assert confirmed == [f'["{namespace}/controller_node"]']


def test_a_recorder_names_the_tail_it_never_received(tmp_path, isolation, ros):
    """The controller says it published 60, 50 come: after close_timeout the recorder
    closes, names the 10 it lacks (the tail: no sequence gap shows it), exits with status
    1 (require_complete) and writes them into its closed record for the launcher."""
    bag = tmp_path / "bag"
    rc, output, _, topic = _end_of_scene(bag, isolation, ros, 2.0, 20, 60)
    assert rc == 1, output
    assert f"missed: {topic} 10 " in output, output
    assert read_metadata(bag)["custom_data"]["recorder_missed"] == f"{topic} 10"


#: One process (as ``grazing run --compose``): a publisher and the recorder's keep-all
#: subscription (RECORDER_QOS); 6000 messages published before any is taken, then 100 more.
_BACKLOG = r"""
import sys, time
import rclpy
from rclpy.duration import Duration
from std_msgs.msg import Float64
from grazing_control.ros.common import PUBLISHER_QOS
from grazing_control.ros.recording.topics import RECORDER_QOS
rclpy.init()
node = rclpy.create_node("backlog")
pub = node.create_publisher(Float64, "backlog", PUBLISHER_QOS)
sub = node.create_subscription(Float64, "backlog", lambda m: None, RECORDER_QOS, raw=True)
end = time.monotonic() + 10.0
while pub.get_subscription_count() == 0 and time.monotonic() < end:
    time.sleep(0.01)
def take():
    n = 0
    while True:
        with sub.handle:
            if sub.handle.take_message(sub.msg_type, True) is None:
                return n
        n += 1
for batch in (6000, 100):
    for i in range(batch):
        pub.publish(Float64(data=float(i)))
    pub.wait_for_all_acked(Duration(seconds=5.0))
    print(take())
"""


@pytest.mark.timeout(60)
def test_a_recorder_6000_messages_behind_in_one_process_still_receives_them_all():
    """Issue 30: a keep-all reader holds 5000 samples by Fast DDS's default; in one process
    a recorder that fell 5000 messages behind (a composed scene at 2000-3500 periods/s,
    the GIL shared with the simulator) took 5000 and then nothing more on that topic (the
    tail of oscillator/state lost, 2794 messages). The nodes' profile
    (fastdds_profile.xml) raises the cap: all 6000, then the next 100."""
    from grazing_control.ros.launcher import FASTDDS_PROFILE, node_env

    env = {**node_env(new_domain()), "FASTDDS_DEFAULT_PROFILES_FILE": str(FASTDDS_PROFILE),
           "FASTRTPS_DEFAULT_PROFILES_FILE": str(FASTDDS_PROFILE)}
    out = subprocess.run([sys.executable, "-c", _BACKLOG], env=env, capture_output=True,
                         text=True, timeout=50)
    assert out.returncode == 0, out.stderr
    assert out.stdout.split() == ["6000", "100"], out.stdout + out.stderr
