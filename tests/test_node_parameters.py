"""What the nodes describe of their parameters is what they accept (issue 27, §2).

``ros2 param describe``, ``dump``, ``get`` and ``set`` are rclpy clients of a node's
parameter services (rcl_interfaces ListParameters, DescribeParameters, GetParameters,
SetParameters); these tests call the same services with rclpy's
:class:`~rclpy.parameter_client.AsyncParameterClient`, as ros2cli does, on nodes built
in the test process (no scene, no subprocess: a node that waits for its peers never
starts here).

* A differential test over EVERY declared parameter of sim_node, controller_node,
  recorder_node and live_node: each end of the range the node describes
  (FloatingPointRange / IntegerRange, step 0, both ends included) is accepted at start
  (a new node with that override) and, for a parameter that is not read-only, through
  SetParameters; the next value beyond each end (the next double, the next integer) is
  refused. rclpy itself accepts a double within a relative 1e-6 of an end; the nodes
  hold the range exactly. A double without a range that refuses inf or NaN says so in
  its additional constraints; a string with "one of:" refuses any other value.
* ``dump`` lists every parameter (GetParameters over every name returned nothing while
  the 1-DOF controller's ``gains`` had no value), and the dump, written as a
  ``--params-file``, starts a new node with the same values.
* A third party's ``use_sim_time``: refused by sim_node (the source of /clock) and by
  recorder_node (its bag states one time base), each naming the parameter, with a log
  line.
"""

from __future__ import annotations

import math
import sys
import threading
from pathlib import Path

import pytest
import rclpy
import yaml
from rcl_interfaces.msg import ParameterType
from rclpy.context import Context
from rclpy.executors import SingleThreadedExecutor
from rclpy.parameter import Parameter, parameter_value_to_python
from rclpy.parameter_client import AsyncParameterClient

from grazing_control.oscillator.ndof.flow import grazing_clearance
from grazing_control.oscillator.ndof.model import load_model
from grazing_control.ros.controller_node import ControllerNode
from grazing_control.recordings.rig_mock import RigMock
from grazing_control.ros.effort_bridge import EffortBridge
from grazing_control.ros.live_node import LiveNode
from grazing_control.ros.recorder_node import RecorderNode
from sim_node.sim_node import SimNode
from test_closed_loop import new_domain
from test_rig_drivers import write_rig_bag

pytestmark = pytest.mark.timeout(300)

FINITE = sys.float_info.max


@pytest.fixture(scope="module")
def context():
    """One rclpy context on a domain of its own for the module's nodes."""
    ctx = Context()
    rclpy.init(context=ctx, domain_id=new_domain())
    yield ctx
    rclpy.shutdown(context=ctx)


class Spun:
    """A node spun in a thread beside a client node whose parameter client calls it."""

    def __init__(self, context, node):
        self.node = node
        self.client_node = rclpy.create_node("param_client", context=context)
        self.client = AsyncParameterClient(self.client_node, node.get_fully_qualified_name())
        self.executor = SingleThreadedExecutor(context=context)
        self.executor.add_node(node)
        self.executor.add_node(self.client_node)
        self._stop = False
        self.thread = threading.Thread(target=self._spin, daemon=True)
        self.thread.start()
        assert self.client.wait_for_services(30.0)

    def _spin(self):
        while not self._stop:
            self.executor.spin_once(timeout_sec=0.05)

    def call(self, future, timeout=30.0):
        event = threading.Event()
        future.add_done_callback(lambda _f: event.set())
        assert event.wait(timeout), "no answer from the parameter service"
        return future.result()

    def close(self):
        self._stop = True
        self.thread.join(10)
        self.executor.shutdown()
        self.client_node.destroy_node()
        self.node.destroy_node()


def close_node(node):
    """What a node holds beyond rclpy: the recorder's bag, the live view's server."""
    if isinstance(node, RecorderNode):
        node.close()
    elif isinstance(node, LiveNode):
        node.on_exit()


class NodeKind:
    """How to build one node in the test process with parameter overrides."""

    def __init__(self, factory, base=None, fresh=None):
        self.factory = factory
        self.base = base or {}          # overrides every build needs
        self.fresh = fresh              # overrides made anew for each build (bag dirs)

    def build(self, context, overrides=None, services=True):
        values = {**self.base, **(self.fresh() if self.fresh else {}), **(overrides or {})}
        return self.factory(context=context, start_parameter_services=services,
                            parameter_overrides=[Parameter(name, value=value)
                                                 for name, value in values.items()])

    def accepts(self, context, overrides):
        """(accepted at start, the refusal's text). The node is built without rclpy's
        parameter services (what it accepts at start is its constructor's, and the six
        services were a quarter of the module's CPU, built and torn down per probe)."""
        try:
            node = self.build(context, overrides, services=False)
        except Exception as exc:     # noqa: BLE001 - rclpy's and the node's refusals
            return False, f"{type(exc).__name__}: {' '.join(str(exc).split())}"
        close_node(node)
        node.destroy_node()
        return True, ""


def kinds(tmp_path):
    count = iter(range(10**6))
    return {
        "sim_node": NodeKind(SimNode),
        "controller_node": NodeKind(ControllerNode),
        "recorder_node": NodeKind(RecorderNode, fresh=lambda: {
            "output": str(tmp_path / f"bag{next(count)}")}),
        "live_node": NodeKind(LiveNode, base={"port": 0}),
        "effort_bridge": NodeKind(EffortBridge),
        "rig_mock": NodeKind(RigMock, base={"bag": str(write_rig_bag(tmp_path / "rig")[2])}),
    }


def probes(d):
    """(value, described as accepted) at the ends of a descriptor's range and beyond."""
    if d.type == ParameterType.PARAMETER_DOUBLE and d.floating_point_range:
        r = d.floating_point_range[0]
        assert r.step == 0.0
        lo, hi = min(r.from_value, r.to_value), max(r.from_value, r.to_value)
        out = [(lo, True), (hi, True), (math.nan, False)]
        out += [(math.nextafter(lo, -math.inf), False)] if lo > -math.inf else []
        out += [(math.nextafter(hi, math.inf), False)] if hi < math.inf else []
        return out
    if d.type == ParameterType.PARAMETER_INTEGER and d.integer_range:
        r = d.integer_range[0]
        assert r.step in (0, 1)
        lo, hi = min(r.from_value, r.to_value), max(r.from_value, r.to_value)
        return ([(lo, True), (hi, True)] + ([(lo - 1, False)] if lo > -2**63 else [])
                + ([(hi + 1, False)] if hi < 2**63 - 1 else []))
    if d.type == ParameterType.PARAMETER_STRING and \
            d.additional_constraints.startswith("one of: "):
        return [("no such choice", False)]
    return []


def unconstrained_probes(d):
    """Values a parameter without a range or choices accepts unless its additional
    constraints say otherwise."""
    if d.type == ParameterType.PARAMETER_DOUBLE and not d.floating_point_range:
        return [-math.inf, -FINITE, 0.0, FINITE, math.inf, math.nan]
    if d.type == ParameterType.PARAMETER_INTEGER and not d.integer_range:
        return [-2**63, 0, 2**63 - 1]
    if d.type == ParameterType.PARAMETER_BOOL:
        return [False, True]
    return []


def same(a, b) -> bool:
    return a == b or (isinstance(a, float) and isinstance(b, float)
                      and math.isnan(a) and math.isnan(b))


# -------------------------------------------------- the differential test of ranges
#: (overrides, the parameters probed there; None: all): the defaults, and for sim_node
#: a delay: pulse_width's range is [0, 0] while actuation_delay is 0 (a pulse is centred
#: at the actuation time), and with a delay it is probed too. (There omega's range is
#: narrowed by the delay, which its constraints state: actuation_delay < 2 pi / omega.)
CONTEXTS = {"sim_node": (({}, None), ({"actuation_delay": 1.0}, {"pulse_width"})),
            "controller_node": (({}, None),), "recorder_node": (({}, None),),
            "live_node": (({}, None),), "effort_bridge": (({}, None),),
            "rig_mock": (({}, None),)}


@pytest.mark.parametrize("name", sorted(CONTEXTS))
def test_every_described_range_end_is_accepted_and_every_value_beyond_refused(
        context, tmp_path, name):
    """ros2 param describe against the node's validator, over every parameter: at start
    (read-only ones too) and through SetParameters (the others). Before: 14 simulator and
    9 controller range ends refused (0 < zeta < 1 described as [0, 1], finite values as
    [0, inf]), and 3600.0000000000005 accepted as diagnostics_period <= 3600."""
    kind = kinds(tmp_path)[name]
    wrong = []
    probed = 0
    for ctx, only in CONTEXTS[name]:
        spun = Spun(context, kind.build(context, ctx))
        try:
            names = sorted(spun.call(spun.client.list_parameters()).result.names)
            descriptors = spun.call(spun.client.describe_parameters(names)).descriptors
            originals = spun.call(spun.client.get_parameters(names)).values
            assert len(descriptors) == len(originals) == len(names)
            for pname, d, original in zip(names, descriptors, originals):
                cases = [(v, ok) for v, ok in probes(d)]
                cases += [(v, None) for v in unconstrained_probes(d)]
                for value, described in cases:
                    if pname in ctx or (only is not None and pname not in only):
                        continue
                    probed += 1
                    at_start, why = kind.accepts(context, {**ctx, pname: value})
                    via_set = None
                    if not d.read_only:
                        res = spun.call(spun.client.set_parameters(
                            [Parameter(pname, value=value)])).results[0]
                        via_set, why = res.successful, why or res.reason
                        if res.successful:         # back to the node's value
                            back = spun.call(spun.client.set_parameters([Parameter(
                                pname, value=parameter_value_to_python(original))]))
                            assert back.results[0].successful, back
                    got = {at_start} | ({via_set} if via_set is not None else set())
                    if described is None:       # no range: a refusal must be stated
                        if got != {True} and not d.additional_constraints:
                            wrong.append(f"{pname}={value!r} refused ({why}) though "
                                         "described without range or constraints")
                    elif got != {described}:
                        wrong.append(f"{pname}={value!r} described as "
                                     f"{'inside' if described else 'outside'} "
                                     f"{_range(d)} but at start "
                                     f"{'accepted' if at_start else 'refused'}"
                                     + ("" if via_set is None else ", by SetParameters "
                                        f"{'accepted' if via_set else 'refused'}")
                                     + (f": {why}" if why else ""))
        finally:
            close_node(spun.node)
            spun.close()
    assert probed >= 10          # the node was probed (live_node: 17 values)
    assert not wrong, "\n".join(wrong)


def _range(d) -> str:
    ranges = d.floating_point_range or d.integer_range
    if not ranges:
        return d.additional_constraints
    return f"[{ranges[0].from_value!r}, {ranges[0].to_value!r}]"


def test_pulse_width_is_described_up_to_the_last_pulse_that_fits_the_period(context):
    """With actuation_delay 1.0 the pulse ends within the delay (pulse_width <= 2.0);
    with the delay 0.5 T + 1 within the period (delay + pulse_width / 2 < T)."""
    kind = NodeKind(SimNode)
    node = kind.build(context, {"actuation_delay": 1.0})
    period = 2.0 * math.pi / node.get_parameter("omega").value
    hi = node.describe_parameter("pulse_width").floating_point_range[0].to_value
    delay_hi = node.describe_parameter("actuation_delay").floating_point_range[0].to_value
    node.destroy_node()
    assert hi == 2.0 and delay_hi == math.nextafter(period, 0.0)
    node = kind.build(context, {"actuation_delay": period / 2 + 1.0})
    hi = node.describe_parameter("pulse_width").floating_point_range[0].to_value
    node.destroy_node()
    delay = period / 2 + 1.0
    assert delay + hi / 2 < period <= delay + math.nextafter(hi, math.inf) / 2
    assert hi == pytest.approx(2 * (period - delay), rel=1e-12)


def test_an_n_dof_controller_describes_and_accepts_the_delays_of_its_model(context):
    """With model_file the period is the model's (two_mass_chain: omega 0.5, T = 4 pi,
    longer than the 1-DOF study's 9.42): a delay of 12 is described and accepted, the
    next double below 4 pi is the range's end, and 4 pi is refused."""
    chain = str(Path(__file__).resolve().parents[1] / "config" / "models"
                / "two_mass_chain.yaml")
    base = {"model_file": chain, "gains": [0.1, 0.0, 0.0, 0.0]}
    kind = NodeKind(ControllerNode, base=base)
    node = kind.build(context, {"actuation_delay": 12.0})
    hi = node.describe_parameter("actuation_delay").floating_point_range[0].to_value
    node.destroy_node()
    assert hi == math.nextafter(4 * math.pi, 0.0)
    assert kind.accepts(context, {"actuation_delay": hi})[0]
    assert not kind.accepts(context, {"actuation_delay": 4 * math.pi})[0]


def test_an_n_dof_simulator_describes_its_model_s_period_and_what_it_does_not_build(
        context):
    """With model_file, sim_node's times are bounded by the model's period (4 pi for
    two_mass_chain): the ends of actuation_delay's and pulse_width's ranges are
    accepted, the next doubles refused; what it does not build (the compliant stop's
    damping) states that only its default is valid, and a refusal says why; the sensor of
    the stream, the velocity and measurement noise at Pi2, the drifting wall and the
    start state0 are built (issue 32): accepted, state0 declared as a double array
    (empty: X**)."""
    chain = str(Path(__file__).resolve().parents[1] / "config" / "models"
                / "two_mass_chain.yaml")
    kind = NodeKind(SimNode, base={"model_file": chain})
    node = kind.build(context)
    ranges = {n: node.describe_parameter(n).floating_point_range[0]
              for n in ("actuation_delay", "pulse_width")}
    noise = node.describe_parameter("contact_damping").additional_constraints
    start = node.get_parameter("state0").value
    drift = node.describe_parameter("delta_d_drift").floating_point_range[0]
    node.destroy_node()
    assert list(start) == []
    assert ranges["actuation_delay"].to_value == math.nextafter(4 * math.pi, 0.0)
    assert ranges["pulse_width"].to_value == 0.0
    for name, r in ranges.items():
        assert kind.accepts(context, {name: r.to_value})[0], name
        assert not kind.accepts(context, {name: math.nextafter(r.to_value, math.inf)})[0]
    assert noise.startswith("only its default 0.0 with model_file")
    ok, why = kind.accepts(context, {"contact_damping": 1e-4})
    assert not ok and "contact_damping=0.0001 is invalid with model_file" in why
    assert kind.accepts(context, {"delta_d_drift": 1e-4})[0]
    # |delta_d_drift| <= the model's d* (3.1885; the 1-DOF d* at its omega is not it),
    # the ends accepted, the next doubles and 1e308 refused naming it (issue 32)
    d_star = grazing_clearance(load_model(chain))
    assert (drift.from_value, drift.to_value) == (-d_star, d_star)
    for value in (d_star, -d_star):
        assert kind.accepts(context, {"delta_d_drift": value})[0], value
    for value in (math.nextafter(d_star, math.inf), 1e308):
        ok, why = kind.accepts(context, {"delta_d_drift": value})
        assert not ok and "delta_d_drift" in why and repr(d_star) in why, why
    assert kind.accepts(context, {"sensor_noise": 1e-4, "sensor_velocity": False})[0]
    assert kind.accepts(context, {"noise": 1e-4, "measurement_noise": 1e-4})[0]
    assert kind.accepts(context, {"state0": [0.0, 0.0, 0.0, 0.0]})[0]
    ok, why = kind.accepts(context, {"state0": [0.0, 0.0]})
    assert not ok and "state0=[0.0, 0.0] is invalid: valid is 2n = 4" in why


# ------------------------------------------------------------- dump and its round trip
def dump(spun) -> dict:
    """``ros2 param dump`` (ros2param/verb/dump.py): ListParameters, then GetParameters
    over every name, as one YAML mapping {full name: {ros__parameters: {...}}}."""
    names = sorted(spun.call(spun.client.list_parameters()).result.names)
    values = spun.call(spun.client.get_parameters(names)).values
    assert len(values) == len(names), (
        f"GetParameters over {len(names)} names answered {len(values)} values")
    return {spun.node.get_fully_qualified_name(): {"ros__parameters": {
        n: parameter_value_to_python(v) for n, v in zip(names, values)}}}


@pytest.mark.parametrize("factory, overrides", [
    (ControllerNode, {"c1": -0.25, "c2": 1.5, "enable_after": 7, "saturation": 0.5}),
    (SimNode, {"delta_d": -5e-6, "max_periods": 11, "noise": 1e-6}),
], ids=["controller_node", "sim_node"])
def test_dump_lists_every_parameter_and_starts_a_new_node_with_the_same_values(
        context, tmp_path, factory, overrides):
    """The 1-DOF controller's ``gains`` is an empty double array (it had no value: a get
    over every name returned nothing and ros2 param dump printed ``ros__parameters:
    {}``); the dump, given to a new node as ``--params-file``, gives the same values."""
    spun = Spun(context, NodeKind(factory).build(context, overrides))
    try:
        first = dump(spun)
    finally:
        spun.close()
    (key, body), = first.items()
    params = body["ros__parameters"]
    assert len(params) > 20 and all(params[k] == v for k, v in overrides.items())
    if factory is ControllerNode:
        assert params["gains"] == []
    path = tmp_path / "dump.yaml"
    path.write_text(yaml.dump(first, default_flow_style=False))   # as ros2 param dump
    node = factory(context=context, cli_args=["--ros-args", "--params-file", str(path)])
    spun = Spun(context, node)
    try:
        second = dump(spun)
    finally:
        spun.close()
    again = second[key]["ros__parameters"]
    assert sorted(again) == sorted(params)
    assert [k for k in params if not same(params[k], again[k])] == []


# ------------------------------------------------------------- use_sim_time, third party
def test_use_sim_time_is_refused_by_the_simulator_and_the_recorder_naming_it(
        context, tmp_path, capfd):
    """sim_node publishes /clock: on simulation time its own timers would wait for it
    (with live_changes a realtime scene froze, no sample nor /clock for > 170 s); the
    recorder's bag states the time base chosen at start. Each refuses, naming the
    parameter, and logs the attempt; a node started with it says so in one line."""
    for node, text in ((SimNode(context=context), "use_sim_time=true is invalid for "
                        "sim_node: valid is false only"),
                       (kinds(tmp_path)["recorder_node"].build(context),
                        "use_sim_time=true is invalid while recording: valid is false")):
        spun = Spun(context, node)
        try:
            res = spun.call(spun.client.set_parameters(
                [Parameter("use_sim_time", value=True)])).results[0]
            got = spun.call(spun.client.get_parameters(["use_sim_time"])).values[0]
        finally:
            close_node(node)
            spun.close()
        assert not res.successful and text in res.reason, res
        assert got.bool_value is False
    err = capfd.readouterr().err
    assert err.count("parameter change refused: use_sim_time=true is invalid") == 2, err
    ok, why = NodeKind(SimNode).accepts(context, {"use_sim_time": True})
    assert not ok and "use_sim_time=true is invalid for sim_node" in why
