"""live_node: the scene's CDR messages over the Foxglove WebSocket protocol (issue 19 §1).

Real processes over Fast DDS on a domain of their own (:func:`new_domain`), and a real
WebSocket client speaking the Foxglove protocol (tests/foxglove_client.py): it reads the
advertised channels, subscribes, receives messageData frames and decodes each payload
against the schema the server advertised (mcap_ros2's ros2msg parser, independent of
the node, which never decodes what it forwards).
"""

from __future__ import annotations

import base64
import glob
import json
import math
import os
import shutil
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path
from types import SimpleNamespace

import pytest
from mcap.reader import make_reader
from mcap_ros2._dynamic import generate_dynamic

from grazing_control.oscillator.params import OscillatorParams
from grazing_control.ros import launcher
from grazing_control.ros.live_node import LIVE_TOPICS
from grazing_control.ros.recording import message_definition
from foxglove_client import FoxgloveClient, parse_message_data
from test_closed_loop import NO_WATCHDOG, new_domain

ROOT = Path(__file__).resolve().parents[1]
LIVE = "grazing_control.ros.live_node"


def free_port() -> int:
    """A TCP port nobody listens on now (the system's choice)."""
    with socket.socket() as sock:
        sock.bind(("127.0.0.1", 0))
        return sock.getsockname()[1]


def start_live(domain, port, ready=True, **params):
    """live_node as a process; with ``ready``, return once it says it serves (its first
    line), so that a signal cannot reach it while it is still being built."""
    proc = subprocess.Popen(
        launcher.node_command(LIVE, (), {"port": port, **params}),
        env=launcher.node_env(domain), stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
        process_group=0)
    proc.first = b""
    if ready:
        proc.first = proc.stdout.readline()      # the node exits or logs: never hangs
        assert b"live view on ws://" in proc.first, proc.first
    return proc


def stop(proc, timeout=20):
    """SIGTERM (handled as Ctrl-C), then the whole output; SIGKILL if it hangs."""
    if proc.poll() is None:
        proc.terminate()
    try:
        out, _ = proc.communicate(timeout=timeout)
    except subprocess.TimeoutExpired:
        proc.kill()
        out, _ = proc.communicate()
    return (proc.first + out).decode(errors="replace")


def decode(channel, payload):
    """A messageData payload decoded with the channel's advertised ros2msg schema."""
    assert channel["encoding"] == "cdr" and channel["schemaEncoding"] == "ros2msg"
    return generate_dynamic(channel["schemaName"], channel["schema"])[
        channel["schemaName"]](payload)


# ------------------------------------------------------------------------ refusals
@pytest.mark.parametrize("value, reason", [
    ("70000", "out of range. Min: 0, Max: 65535"),
    ("-1", "out of range. Min: 0, Max: 65535"),
    ("abc", "expected type INTEGER"),
    ("80.0", "expected type INTEGER"),
])
def test_a_bad_port_is_refused_in_one_line_naming_it_and_its_range(value, reason):
    proc = subprocess.run(launcher.node_command(LIVE) + ["-p", f"port:={value}"],
                          env=launcher.node_env(new_domain()), capture_output=True,
                          text=True, timeout=60)
    lines = [line for line in (proc.stdout + proc.stderr).splitlines() if line.strip()]
    assert proc.returncode == 2
    assert len(lines) == 1 and f"port={value} is invalid" in lines[0] and reason in lines[0]
    assert "Traceback" not in proc.stderr


def test_a_port_in_use_is_one_line_and_exit_status_2():
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        proc = start_live(new_domain(), port, ready=False)
        proc.wait(60)
        out = stop(proc)
    lines = [line for line in out.splitlines() if line.strip()]
    assert proc.returncode == 2, out
    assert len(lines) == 1 and f"port={port} is in use on 127.0.0.1" in lines[0], out


def test_grazing_run_refuses_a_bad_or_busy_live_port_before_starting_a_node():
    grazing = [sys.executable, "-m", "grazing_control.cli"]
    bad = subprocess.run(grazing + ["run", "--live", "65536", "--periods", "5"],
                         capture_output=True, text=True, timeout=60)
    assert bad.returncode == 2
    assert "--live: '65536' is invalid: valid range is an integer 0..65535" in bad.stderr
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        t0 = time.monotonic()
        used = subprocess.run(grazing + ["run", "--live", str(port), "--periods", "5"],
                              capture_output=True, text=True, timeout=60)
    lines = [line for line in used.stderr.splitlines() if line.strip()]
    assert used.returncode == 2
    assert lines == [f"grazing run: error: --live {port}: port {port} is in use on 127.0.0.1 "
                     "(Address already in use): stop the other server or choose another port"]
    assert time.monotonic() - t0 < 30          # refused up front, no scene started


# ------------------------------------------------------------- protocol and values
def test_channels_advertise_cdr_with_the_ros2msg_definitions_of_the_recorder():
    port = free_port()
    proc = start_live(new_domain(), port)
    try:
        # every topic named: the server may advertise them in several frames
        client = FoxgloveClient(port, topics=[f"/{name}" for name in LIVE_TOPICS])
        client.close()
    finally:
        out = stop(proc)
    assert client.subprotocol == "foxglove.sdk.v1"
    assert client.server_info["op"] == "serverInfo"
    assert set(client.channels) == {f"/{name}" for name in LIVE_TOPICS}, out
    for name, kind in LIVE_TOPICS.items():
        ch = client.channels[f"/{name}"]
        assert ch["encoding"] == "cdr"
        assert ch["schemaEncoding"] == "ros2msg"
        assert ch["schemaName"] == kind
        assert ch["schema"] == message_definition(kind)   # what the bags hold
    assert proc.returncode == 0, out
    assert "live view stopped: forwarded nothing" in out


def test_what_a_node_publishes_arrives_byte_for_byte_and_decodes_to_the_same_values():
    """The test process publishes JointStates (reliable, as the simulator) with values
    of its own choosing; each frame the client receives decodes to one of them, and
    its length is that of rclpy's serialization (the padding bytes may differ: rclpy
    leaves them unset)."""
    import rclpy
    from rclpy.context import Context
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState
    from grazing_control.ros.common import PUBLISHER_QOS

    domain = new_domain()
    port = free_port()
    proc = start_live(domain, port)
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("publisher", context=context)
    pub = node.create_publisher(JointState, "oscillator/pi2", PUBLISHER_QOS)
    sent = {}
    try:
        client = FoxgloveClient(port, topics=["/oscillator/pi2"])
        k = 0
        end = time.monotonic() + 30
        while len(client.messages) < 50 and time.monotonic() < end:
            msg = JointState(name=["mass"], position=[0.125 * k - 3.0],
                             velocity=[-1e-7 * k], effort=[0.5 ** k])
            msg.header.stamp.sec, msg.header.stamp.nanosec = k, 7 * k
            sent[(k, 7 * k)] = msg
            pub.publish(msg)
            k += 1
            time.sleep(0.01)
        client.close()
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
        out = stop(proc)
    assert len(client.messages) >= 50, out
    channel = client.channels["/oscillator/pi2"]
    for topic, stamp, payload in client.messages:
        assert topic == "/oscillator/pi2"
        got = decode(channel, payload)
        want = sent[(got.header.stamp.sec, got.header.stamp.nanosec)]
        assert len(payload) == len(serialize_message(want))
        assert list(got.name) == ["mass"]
        assert list(got.position) == list(want.position)
        assert list(got.velocity) == list(want.velocity)
        assert list(got.effort) == list(want.effort)
        assert (got.header.stamp.sec, got.header.stamp.nanosec) == (
            want.header.stamp.sec, want.header.stamp.nanosec)
        assert abs(stamp - time.time_ns()) < 120e9      # reception time, ns since epoch
    assert proc.returncode == 0
    assert "live view stopped: forwarded /oscillator/pi2 " in out


def test_a_malformed_message_is_forwarded_as_is_and_the_node_keeps_running():
    """Bytes that decode to no JointState (a stray publisher's serialized garbage) reach
    the viewer unchanged, and the node goes on forwarding the well-formed ones."""
    import rclpy
    from rclpy.context import Context
    from rclpy.serialization import serialize_message
    from sensor_msgs.msg import JointState

    from grazing_control.ros.common import PUBLISHER_QOS

    domain = new_domain()
    port = free_port()
    proc = start_live(domain, port)
    context = Context()
    rclpy.init(context=context, domain_id=domain)
    node = rclpy.create_node("stray", context=context)
    pub = node.create_publisher(JointState, "oscillator/pi2", PUBLISHER_QOS)
    garbage = b"\x00\x01\x00\x00" + bytes(range(7, 43))   # 40 bytes: no DDS padding
    good = JointState(name=["mass"], position=[1.5], velocity=[-2.0], effort=[0.0])
    try:
        client = FoxgloveClient(port, topics=["/oscillator/pi2"])
        end = time.monotonic() + 30
        while time.monotonic() < end and not (
                {p for _, _, p in client.messages} >= {garbage}
                and len(client.messages) > 20 and client.messages[-1][2] != garbage):
            pub.publish(garbage)            # rclpy publishes bytes as serialized data
            pub.publish(good)
            time.sleep(0.01)
        client.close()
    finally:
        node.destroy_node()
        rclpy.shutdown(context=context)
        out = stop(proc)
    payloads = [p for _, _, p in client.messages]
    assert garbage in payloads, out
    assert len(serialize_message(good)) in {len(p) for p in payloads if p != garbage}
    decoded = decode(client.channels["/oscillator/pi2"], payloads[-1])
    assert list(decoded.position) == [1.5] and list(decoded.velocity) == [-2.0]
    assert proc.returncode == 0, out
    assert "Traceback" not in out


def test_parse_message_data_reads_the_specified_layout():
    frame = bytes([1]) + (7).to_bytes(4, "little") + (2**40 + 3).to_bytes(8, "little") + b"xy"
    assert parse_message_data(frame) == (7, 2**40 + 3, b"xy")
    with pytest.raises(ValueError, match="opcode 0x2"):
        parse_message_data(bytes([2]) + frame[1:])


def _paths(node):
    """Every message path (``/topic.field...``) in a layout's panel configs."""
    if isinstance(node, dict):
        for key, value in node.items():
            if key == "value" and isinstance(value, str) and value.startswith("/"):
                yield value
            else:
                yield from _paths(value)
    elif isinstance(node, list):
        for value in node:
            yield from _paths(value)


def test_the_shipped_layout_plots_fields_that_exist_on_the_channels_the_node_serves():
    """config/live_layout.json: every panel in the layout tree has a config, and every
    message path names a forwarded topic and a numeric field of its message type."""
    import json

    from grazing_control.ros.recording.topics import message_class

    layout = json.loads((ROOT / "config" / "live_layout.json").read_text())
    panels = set()
    stack = [layout["layout"]]
    while stack:
        node = stack.pop()
        if isinstance(node, str):
            panels.add(node)
        else:
            stack += [node["first"], node["second"]]
    assert panels == set(layout["configById"])
    poincare = layout["configById"]["Plot!poincare"]
    assert poincare["xAxisVal"] == "custom"
    assert poincare["xAxisPath"]["value"] == "/oscillator/pi2.position[0]"
    assert [p["value"] for p in poincare["paths"]] == ["/oscillator/pi2.velocity[0]"]
    paths = list(_paths(layout))
    assert len(paths) >= 8
    for path in paths:
        topic, _, field = path.partition(".")
        assert topic.lstrip("/") in LIVE_TOPICS, path
        value = message_class(LIVE_TOPICS[topic.lstrip("/")])()
        for part in field.split("."):
            name, _, index = part.partition("[")
            value = getattr(value, name)
            if index:                  # a float64[] field (array('d')): an element is a float
                assert getattr(value, "typecode", None) == "d", path
                value = 0.0
        assert isinstance(value, float), path
    # the node's --help says which time the layout plots (it said header stamps while
    # every path used reception time, issue 27 §2): reception time, the one time every
    # topic has (oscillator/latency, a Float64, has no header stamp)
    methods = []
    stack = [layout["configById"]]
    while stack:
        node = stack.pop()
        if isinstance(node, dict):
            methods += [v for k, v in node.items() if k == "timestampMethod"]
            stack += list(node.values())
        elif isinstance(node, list):
            stack += node
    assert len(methods) >= len(paths) and set(methods) == {"receiveTime"}, methods
    from grazing_control.ros import live_node

    usage = " ".join(live_node.__doc__.split())
    assert "the shipped layout (config/live_layout.json, docs/live.md) plots against it" \
        in usage and "header stamp is the simulation time" in usage, usage
    assert "which the shipped layout plots against" not in usage


# --------------------------------------------------------------------- a real scene
def _bag_messages(bag_dir):
    """{topic: {payload bytes}} of a recorded bag (the MCAP file's raw messages)."""
    out = {}
    (path,) = glob.glob(os.path.join(bag_dir, "*.mcap"))
    with open(path, "rb") as fh:
        for _schema, channel, message in make_reader(fh).iter_messages():
            out.setdefault(channel.topic, set()).add(bytes(message.data))
    return out


#: The scene's topics both clients read.
WANTED = ("/oscillator/pi2", "/controller/velocity_correction", "/oscillator/impact",
          "/oscillator/state")
#: The protocol authors' client (tests/js: @foxglove/ws-protocol, @foxglove/rosmsg2-
#: serialization, pinned by its package-lock.json; node_modules is installed here).
JS = ROOT / "tests" / "js"


def js_client():
    """(the command running tests/js/live_client.mjs, None) or (None, why it cannot run):
    node and npm must exist, and ``npm ci`` installs the locked packages into
    tests/js/node_modules (again when package-lock.json is newer than the install)."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if not (node and npm):
        return None, "node and npm are needed for the protocol authors' client (tests/js)"
    installed = JS / "node_modules" / ".package-lock.json"
    if not installed.exists() or \
            installed.stat().st_mtime < (JS / "package-lock.json").stat().st_mtime:
        try:
            done = subprocess.run([npm, "ci", "--no-audit", "--no-fund"], cwd=JS,
                                  capture_output=True, text=True, timeout=300)
        except subprocess.TimeoutExpired:
            return None, "npm ci in tests/js took over 300 s (no registry?)"
        if done.returncode != 0:
            tail = " ".join((done.stderr or done.stdout).split())[-300:]
            return None, f"npm ci in tests/js failed (no registry?): {tail}"
    return [node, str(JS / "live_client.mjs")], None


@pytest.fixture(scope="module")
def live_scene(tmp_path_factory):
    """``grazing run --live PORT --periods 200 --bag DIR`` (the launcher's API), read while
    it runs by two clients at once: tests/foxglove_client.py and, where node exists, the
    protocol authors' own (tests/js/live_client.mjs). One scene for both tests."""
    tmp = tmp_path_factory.mktemp("live_scene")
    command, js_skip = js_client()      # installed before the scene: it must connect
    port = free_port()
    bag = tmp / "bag"
    result = {}
    # realtime at 300x: the 200 periods last ~6 s of wall time, time for the clients to
    # connect and subscribe (a lockstep scene can end in ~1 s, before they have: the live
    # view is a best-effort reader the scene never waits for; a rerun in the full suite).
    # Not in the FIFO group, nor under SCHED_FIFO (tests/conftest.py): no assertion
    # needs a deadline met (the watchdog is off, every check compares what the clients
    # got with the bag); the
    # clients connected and both tests passed at load 7.6-8.4 (other sessions' tests and
    # benchmarks), twice more with two busy-looping processes beside them as the suite's
    # other workers (2026-11-28); 12 s less of the suite's serial tail.
    scene = threading.Thread(target=lambda: result.update(res=launcher.run(
        None, None, bag, 200, domain_id=new_domain(), live=port, timeout=240,
        sim_overrides={"mode": "realtime", "time_scale": 300.0, **NO_WATCHDOG},
        controller_overrides={"thread_priority": 0}, log_dir=tmp / "logs")))
    js = None
    if command:
        js = subprocess.Popen(command + [f"ws://127.0.0.1:{port}", ",".join(WANTED), "240"],
                              stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    scene.start()
    try:
        # the topics named: the client subscribes once all four are advertised (the
        # server may advertise a starting node's channels in several frames)
        client = FoxgloveClient(port, topics=WANTED, timeout=60)
    finally:
        scene.join(300)
    client.wait_for(lambda c: False, 1.0)        # the last frames in flight
    client.close()
    js_result = None
    if js is not None:
        try:
            out, err = js.communicate(timeout=60)    # it ends when the server closes
        except subprocess.TimeoutExpired:
            js.kill()
            out, err = js.communicate()
        js_result = (js.returncode, out, err)
    return SimpleNamespace(res=result["res"], bag=bag, client=client, js=js_result,
                           js_skip=js_skip)


def test_grazing_run_live_streams_the_scene_that_the_bag_records(live_scene):
    """The client, connected while the scene starts, receives Π2 samples, corrections,
    impacts and state; every payload is one the recorder stored (the same bytes) and
    decodes against the advertised schema to the bag's values."""
    res, client = live_scene.res, live_scene.client
    assert res.ok and res.live == 0, (res, Path(res.logs["live_node"]).read_text())
    recorded = _bag_messages(live_scene.bag)
    got = {}
    for topic, _stamp, payload in client.messages:
        got.setdefault(topic, []).append(payload)
    for topic in WANTED:
        assert got.get(topic), (topic, {t: len(v) for t, v in got.items()})
        channel = client.channels[topic]
        reader = generate_dynamic(channel["schemaName"], channel["schema"])
        for payload in got[topic]:
            assert payload in recorded[topic]          # the scene's own message
            assert reader[channel["schemaName"]](payload) is not None
    log = Path(res.logs["live_node"]).read_text()
    assert "live view stopped: forwarded" in log
    print({t: (len(v), len(recorded.get(t, ()))) for t, v in got.items()})


def _plain(msg):
    """A message decoded by mcap_ros2 as nested dicts and lists, as the JS client's JSON
    writes it (non-finite doubles as strings)."""
    if hasattr(msg, "__slots__"):
        return {k: _plain(getattr(msg, k)) for k in msg.__slots__}
    if isinstance(msg, (list, tuple)):
        return [_plain(v) for v in msg]
    if isinstance(msg, float) and not math.isfinite(msg):
        return {"nan": "NaN", "inf": "Infinity", "-inf": "-Infinity"}[repr(msg)]
    return msg


def test_the_protocol_authors_client_subscribes_and_decodes_the_scene(live_scene):
    """@foxglove/ws-protocol's FoxgloveClient (over ws) reads the same scene: it
    negotiates the protocol, sees the four channels as cdr / ros2msg, subscribes, and
    each message it decodes with @foxglove/rosmsg2-serialization (from the advertised
    schema, independent of this package and of mcap_ros2) is a message of the bag, with
    the values mcap_ros2 reads from the bag's bytes: the stamps, x and v of Π2, the
    corrections Delta v, the state samples."""
    if live_scene.js is None:
        pytest.skip(live_scene.js_skip)
    code, out, err = live_scene.js
    assert code == 0 and out, (code, out[-2000:], err[-2000:])
    got = json.loads(out)
    assert got["errors"] == [], got["errors"]
    assert got["subprotocol"] == "foxglove.sdk.v1"     # foxglove.websocket.v1: a 400
    for topic in WANTED:
        ch = got["channels"][topic]
        assert (ch["encoding"], ch["schemaEncoding"]) == ("cdr", "ros2msg")
    recorded = _bag_messages(live_scene.bag)
    counts = {}
    for m in got["messages"]:
        payload = base64.b64decode(m["payload"])
        assert payload in recorded[m["topic"]], m["topic"]    # the scene's own message
        channel = live_scene.client.channels[m["topic"]]
        want = decode(channel, payload)
        assert m["value"] == _plain(want), (m["topic"], m["value"], want)
        counts[m["topic"]] = counts.get(m["topic"], 0) + 1
    assert set(counts) == set(WANTED), counts
    pi2 = [m["value"] for m in got["messages"] if m["topic"] == "/oscillator/pi2"]
    assert all(len(v["position"]) == 1 and len(v["velocity"]) == 1 for v in pi2)
    # the Π2 samples are the scene's: stamps k T of the study's forcing period
    period = 2 * math.pi / OscillatorParams().omega
    for v in pi2:
        t = v["header"]["stamp"]["sec"] + v["header"]["stamp"]["nanosec"] * 1e-9
        assert abs(t / period - round(t / period)) < 1e-6, t
    print(counts)
