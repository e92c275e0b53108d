"""A recorded rig scene replayed through mock hardware: the same commands, bit for bit.

Issue 28's acceptance (docs/rig_scene.md, "Replay through mock hardware"): a
``controller_node`` with the recorded controller's parameters (the bag's parameter record,
``grazing/parameters``) meets ``rig_mock`` replaying the bag (docs/driver_contract.md,
"Mock hardware"): the recorded ``rig/sensor``, ``rig/phase``, ``rig/clock`` and the
recorded ``rig/applied`` (what the hardware did, which the controller's estimator
integrates) in their recorded order; ``rig_mock`` (``compare:=rig/force_pulse``) compares
every ``rig/force_pulse`` of the replay with the recorded one of its section, field by
field as float64 bytes, and exits 1 naming the first difference. Both are processes on a
ROS domain of their own (:func:`grazing_control.ros.launcher.claim_domain`).

The controller's commands are a function of its inputs: the sections from the first
phase reference, the estimate of section k from the stamps of the samples (answered
``answer_lead`` before its last sample, by stamps, not by arrival), what acted at the
sections before k. The last is the one input whose arrival order matters: rig/applied of
section k - 1 must have arrived before the sample that makes section k due (most of a
forcing period after the pulse), in the recording and in the replay; rig_mock replays it
at its recorded place among the samples, and the controller counts one that came after
it was needed (``applied_after_use`` in its summary). The clock relation only measures
the samples' arrival latency (diagnostics): no command depends on it.
"""

from __future__ import annotations

import re
import tempfile
import time
from pathlib import Path

from grazing_control.ros.recording.record import run_parameters

from . import reader

__all__ = ["recorded_controller", "replay_rig", "NOT_SETTINGS", "add_arguments", "main"]

#: Parameters of the record that are not the controller's settings.
NOT_SETTINGS = ("use_sim_time", "start_type_description_service")
PARAMETERS = "/grazing/parameters"


def recorded_controller(bag) -> dict:
    """The controller_node's parameters at its start, from the bag's parameter record,
    less those its rig file sets (:func:`grazing_control.ros.rig_boundary.controller_values`
    derives them again from ``rig_file`` and ``rig_c2``, or for a rig of n masses
    ``rig_mu``: the n-DOF model's and its gains, MASSES_CONTROLLER_KEYS; ``answer_lead``,
    which may be given, is kept). ValueError (one line) when the bag has none or no
    rig_file."""
    from grazing_control.ros.rig_boundary import CONTROLLER_KEYS, MASSES_CONTROLLER_KEYS

    raw = reader.read_raw(bag, [PARAMETERS])
    nodes = run_parameters(reader.decode_strings(raw, PARAMETERS))["nodes"]
    rec = (nodes.get("controller_node") or [None])[0]
    if rec is None:
        raise ValueError(f"bag={bag}: no controller_node parameter record on {PARAMETERS}")
    if not rec.get("rig_file"):
        raise ValueError(f"bag={bag}: the recorded controller_node has no rig_file (not a "
                         "rig scene: replay it with grazing replay)")
    derived = (set(CONTROLLER_KEYS) | set(MASSES_CONTROLLER_KEYS)) - {"answer_lead"}
    return {k: v for k, v in rec.items() if k not in NOT_SETTINGS and k not in derived}


def _summary(log: Path) -> dict:
    lines = [ln for ln in log.read_text(errors="replace").splitlines() if "summary:" in ln]
    return dict(re.findall(r"(\w+)=(\S+)", lines[-1])) if lines else {}


def replay_rig(bag, *, time_scale: float = 1.0, controller_overrides: dict | None = None,
               log_dir=None, timeout: float = 600.0, domain_id=None) -> dict:
    """Replay ``bag`` through rig_mock and a controller_node (module docstring).

    ``controller_overrides`` change the recorded parameters (a negative check: another
    c2 must differ). Returns {"status": rig_mock's exit status (0 identical, 1 a
    difference), "identical", "differing", "missing", "extra" (ints), "first": the
    first difference's line or None, "controller": the controller's summary fields,
    "logs": {node: path}}.
    """
    from grazing_control.ros.launcher import (CONTROLLER_MODULE, claim_domain, start_node,
                                              stop_nodes)

    values = dict(recorded_controller(bag), **(controller_overrides or {}))
    lock = None
    if domain_id is None:
        domain_id, lock = claim_domain()
    tmp = tempfile.TemporaryDirectory(prefix="grazing_rig_replay_")
    logs_at = Path(log_dir) if log_dir is not None else Path(tmp.name)
    logs_at.mkdir(parents=True, exist_ok=True)
    logs = {n: logs_at / f"{n}.log" for n in ("controller_node", "rig_mock")}
    controller = mock = None
    try:
        controller = start_node(CONTROLLER_MODULE, (), values, domain_id=domain_id,
                                log=str(logs["controller_node"]))
        mock = start_node("grazing_control.recordings.rig_mock", (), {
            "bag": str(Path(bag).resolve()), "time_scale": float(time_scale),
            "compare": "rig/force_pulse"}, domain_id=domain_id, log=str(logs["rig_mock"]))
        end = time.monotonic() + timeout
        while mock.poll() is None and time.monotonic() < end:
            if controller.poll() is not None:
                break
            time.sleep(0.1)
    finally:
        stop_nodes([mock])
        stop_nodes([controller])
        if lock is not None:
            lock.close()
    text = logs["rig_mock"].read_text(errors="replace")
    counts = _summary(logs["rig_mock"])
    first = re.search(r"compare: (section .*)", text)
    result = {"status": mock.returncode, "first": first.group(1) if first else None,
              "controller": _summary(logs["controller_node"]),
              "logs": {n: str(p) for n, p in logs.items()}}
    for name in ("identical", "differing", "missing", "extra"):
        result[name] = int(counts.get(name, -1))
    if log_dir is None:
        result["logs"] = {n: p.read_text(errors="replace")[-4000:] for n, p in logs.items()}
        tmp.cleanup()
    return result


# ------------------------------------------------------------------ grazing replay-rig
def add_arguments(parser) -> None:
    parser.add_argument("bag", metavar="BAG", help="a rig scene's bag (directory or .mcap)")
    parser.add_argument("--time-scale", type=float, default=1.0, metavar="S",
                        help="recorded seconds per wall second of the replay (default 1: "
                             "the recorded pace)")
    parser.add_argument("--log-dir", default=None, metavar="DIR",
                        help="keep the controller's and rig_mock's logs here")
    parser.add_argument("--controller-param", dest="overrides", action="append", default=[],
                        metavar="NAME:=VALUE",
                        help="change a recorded controller parameter (YAML value; "
                             "repeatable), e.g. rig_c2:=0.04: the commands then differ")
    parser.add_argument("--timeout", type=float, default=3600.0, metavar="SECONDS")


def main(args) -> int:
    """``grazing replay-rig BAG``: exit 0 when every recorded command came again
    identical, 1 naming the first difference, 2 for bad input."""
    import math

    from grazing_control.support.files import parse_yaml_bytes

    if not (math.isfinite(args.time_scale) and 1e-3 <= args.time_scale <= 1e6):
        raise ValueError(f"--time-scale={args.time_scale!r} is invalid: valid range is "
                         "1e-3..1e6")
    overrides = {}
    for item in args.overrides:
        name, sep, value = item.partition(":=")
        if not sep or not name:
            raise ValueError(f"--controller-param {item!r} is invalid: valid is NAME:=VALUE")
        overrides[name] = parse_yaml_bytes(value.encode(), f"--controller-param {name}")
    recorded_controller(args.bag)          # refuse a bag that is no rig scene first
    res = replay_rig(args.bag, time_scale=args.time_scale, controller_overrides=overrides,
                     log_dir=args.log_dir, timeout=args.timeout)
    print(f"replay of {args.bag} through rig_mock: identical={res['identical']} "
          f"differing={res['differing']} missing={res['missing']} extra={res['extra']}; "
          f"controller applied_after_use={res['controller'].get('applied_after_use')} "
          f"rig_applied={res['controller'].get('rig_applied')}")
    print(f"first difference: {res['first']}" if res["status"] else
          "every recorded command again, bit for bit")
    return 0 if res["status"] == 0 else 1
