"""The options of ``grazing run`` (their names are :func:`grazing_control.ros.launcher.run`'s
keyword arguments), each checked with one line naming its valid range."""

from __future__ import annotations

import argparse
import math

from grazing_control.ros.launcher import MAX_DOMAIN_ID, ParamText, check_domain_id
from grazing_control.support.arguments import finite


def _domain_id(text: str) -> int:
    try:
        return check_domain_id(int(text))
    except ValueError:
        raise argparse.ArgumentTypeError(
            f"{text!r} is invalid: valid range is an integer 0..{MAX_DOMAIN_ID}") from None


def _seconds(text: str) -> float:
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise argparse.ArgumentTypeError(
            f"{text!r} is invalid: valid range is a finite number of seconds > 0")
    return value


def _periods(text: str) -> int:
    try:
        value = int(text)
    except ValueError:
        value = 0
    if not 1 <= value < 2**63:
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: expected an integer in "
                                         "1 .. 2^63 - 1 (sim_node's max_periods)")
    return value


def _key_value(text: str):
    key, sep, value = text.partition(":=")
    if not sep or not key:
        raise argparse.ArgumentTypeError(f"{text!r}: expected KEY:=VALUE")
    return key, ParamText(value)


class _Pairs(argparse.Action):
    """Collect KEY:=VALUE options into a dict."""

    def __call__(self, parser, namespace, values, option_string=None):
        pairs = dict(getattr(namespace, self.dest) or {})
        key, value = values
        pairs[key] = value
        setattr(namespace, self.dest, pairs)


def add_run_arguments(parser) -> None:
    """The options of ``grazing run``; their names are :func:`run`'s keyword arguments."""
    parser.add_argument("--model", default=None, metavar="FILE",
                        help="run an n-DOF scene of this model file (docs/ndof_model.md); "
                             "--controller-params must give its gains (default: the "
                             "study's 1-DOF oscillator)")
    parser.add_argument("--rig", default=None, metavar="FILE",
                        help="run a simulated rig of this rig file (docs/rig.md) in SI at "
                             "physical speed, both nodes speaking the driver contract "
                             "(docs/rig_scene.md); realtime, the gains designed for the "
                             "rig's budget (--controller-param rig_c2:=C2, default the c2 "
                             "of least noise gain; a rig of n masses: its n-DOF model and "
                             "pulse design, --controller-param rig_mu:=MU, default "
                             "grazing design --rig's mu)")
    parser.add_argument("--sim-params", dest="sim_params", default=None,
                        help="sim_node parameter file (default: config/study.yaml)")
    parser.add_argument("--controller-params", dest="controller_params", default=None,
                        help="controller parameter file from `grazing design --out` "
                             "(default: config/controller.yaml)")
    parser.add_argument("--bag", dest="bag_dir", default=None,
                        help="record the scene to this bag directory (default: no recording)")
    parser.add_argument("--periods", type=_periods, default=None,
                        help="forcing periods to simulate, 1 .. 2^63 - 1 (default: the "
                             "parameter file's)")
    parser.add_argument("--delta-d", dest="delta_d", type=finite, default=None,
                        help="Delta d = d - d* (default: the parameter file's)")
    parser.add_argument("--enable-after", dest="enable_after", type=int, default=None,
                        help="first controlled Pi2 sample (default 1000; -1: never)")
    parser.add_argument("--mode", choices=("lockstep", "realtime"), default=None,
                        help="simulator mode (default: the parameter file's, lockstep)")
    parser.add_argument("--domain-id", dest="domain_id", type=_domain_id, default=None,
                        help=f"ROS_DOMAIN_ID of the nodes, 0..{MAX_DOMAIN_ID} (default: a free "
                             "one claimed for this run, so that scenes never mix; printed)")
    parser.add_argument("--timeout", type=_seconds, default=None,
                        help="wall seconds before the scene is stopped (default: none)")
    parser.add_argument("--log-dir", dest="log_dir", default=None,
                        help="write each node's output to LOG_DIR/<node>.log")
    parser.add_argument("--compose", action="store_true",
                        help="run the simulator, the controller and the recorder in one "
                             "process on one executor (docs/nodes.md, \"Composed scene\"; "
                             "default: a process per node)")
    parser.add_argument("--sim-param", dest="sim_overrides", type=_key_value, action=_Pairs,
                        metavar="KEY:=VALUE", help="any sim_node parameter (repeatable)")
    parser.add_argument("--controller-param", dest="controller_overrides", type=_key_value,
                        action=_Pairs, metavar="KEY:=VALUE",
                        help="any controller_node parameter (repeatable)")
