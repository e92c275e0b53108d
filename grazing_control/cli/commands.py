"""The `grazing` command line: design, orbit, continue, simulate, run, demo, robustness.

The model commands (design, orbit, continue, simulate, sweep, figures) each run on the
1-DOF study's model or, with ``--model FILE``, on a model file's (:mod:`.model_file`):
cli/design.py, cli/orbits.py, cli/diagrams.py.

Every subcommand shares --zeta --r --omega --pi2-offset (defaults: the study's set).
Output is human-readable by default; with --json exactly one JSON object goes to
stdout and nothing else. User errors (bad parameters, no orbit) print one line
``grazing: error: ...`` to stderr and exit with status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import json
import os
import re
import sys
import warnings

import numpy as np

from grazing_control.oscillator.params import ParameterError
from grazing_control.support.arguments import finite, integer_at_least, non_negative

from . import model_file
from .common import add_common, add_delay, add_gains, add_method, count, file_path, non_finite, nulls
from .design import cmd_design
from .diagrams import cmd_figures, cmd_sweep
from .orbits import cmd_continue, cmd_orbit, cmd_simulate
from .parameter_file import add_params_option, apply_to_args
from .rig import apply_rig
from .stop import add_run_stop_options, add_stop_options, apply_run_stop

__all__ = ["main", "build_parser"]


class _Parser(argparse.ArgumentParser):
    """argparse with one-line errors: ``grazing <command>: error: ...``, exit status 2.

    A negative number in exponent form (``--delta-d -5e-6 -1e-6``) is a value, not an
    option: argparse's own pattern only knows ``-1`` and ``-1.5``, so the second value of
    a list was taken for an unknown option.
    """

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._negative_number_matcher = _NEGATIVE_NUMBER

    def error(self, message):
        command = self.prog.split()[-1]
        where = "" if command == "grazing" else f"{command}: "
        self.exit(2, f"grazing: error: {where}{message}\n")


_NEGATIVE_NUMBER = re.compile(r"^-(\d+\.?\d*|\.\d+)([eE][-+]?\d+)?$|^-(inf|nan)$", re.IGNORECASE)



# ---------------------------------------------------------------------------- run / demo
@contextlib.contextmanager
def _stdout_to_stderr():
    """Send this process's stdout, and that of the processes it starts, to stderr."""
    sys.stdout.flush()
    try:
        fd = sys.stdout.fileno()
        saved = os.dup(fd)
    except (AttributeError, OSError, ValueError):  # no real file descriptor (captured)
        fd = saved = None
    try:
        if fd is not None:
            os.dup2(sys.stderr.fileno(), fd)
        with contextlib.redirect_stdout(sys.stderr):
            yield
    finally:
        if fd is not None:
            sys.stderr.flush()
            os.dup2(saved, fd)
            os.close(saved)


def _live_port(text: str) -> int:
    """``--live PORT``: an integer 0..65535 (0: any free port, which live_node logs)."""
    try:
        port = int(text)
    except ValueError:
        port = -1
    if not 0 <= port <= 65535:
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: valid range is an integer "
                                         "0..65535 (0: any free port)")
    return port


def _port_in_use(port: int, host: str = "127.0.0.1") -> str | None:
    """Why live_node could not listen on ``host:port``, before any node starts, or None."""
    import socket

    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
        try:
            sock.bind((host, port))
        except OSError as exc:
            return (f"port {port} is in use on {host} ({exc.strerror}): stop the other "
                    "server or choose another port")
    return None


def _check_run_files(args) -> None:
    """Read the files a scene's nodes will read, here and once, before any node starts:
    a FIFO, an alias bomb or a file beyond the limits of
    :func:`grazing_control.support.files.read_yaml_file` is one ParameterError line
    naming the option (a node would block on a FIFO, or take the bomb's memory)."""
    from grazing_control.support.files import YamlFileError, read_yaml_file

    for option, path in (("--sim-params", args.sim_params), ("--model", args.model),
                         ("--controller-params", args.controller_params)):
        if path is not None:
            try:
                read_yaml_file(path)
            except YamlFileError as exc:
                raise ParameterError(f"{option} {exc}") from None
    if getattr(args, "rig", None) is not None:     # the rig file, validated once here
        from grazing_control.plant.rig import load_rig

        from grazing_control.ros.rig_boundary import sim_values

        try:
            sim_values(load_rig(args.rig))   # what sim_node refuses (the rig file)
        except (ParameterError, YamlFileError) as exc:
            raise ParameterError(f"--rig {exc}") from None
    bag = getattr(args, "bag_dir", None)
    if bag is not None and os.path.isdir(bag) and os.listdir(bag):
        # the recorder refuses it (its status 2), but only after every node has started
        raise ParameterError(f"--bag {bag} is invalid: the folder is not empty (a bag is "
                             "written into a new or empty folder; nothing is overwritten)")


def cmd_run(args):
    import dataclasses

    from grazing_control.ros.launcher import run

    _check_run_files(args)
    stop = apply_run_stop(args)     # --stop: the stop model (cli/stop.py), into sim_overrides
    if stop is not None and stop["warning"]:
        print(f"grazing: warning: {stop['warning']}", file=sys.stderr)
    kwargs = {k: v for k, v in vars(args).items()
              if k not in ("func", "command", "json", "stop", "stop_tol")}
    if getattr(args, "live", None):
        busy = _port_in_use(args.live)
        if busy:
            print(f"grazing run: error: --live {args.live}: {busy}", file=sys.stderr)
            return 2
    if not args.json:
        result = run(**kwargs)
        _record_stop(result, stop)
        print(result)
        if stop is not None:
            print(f"stop model = {stop['reason']}")
        return result.exit_code
    with _stdout_to_stderr():  # stdout: the one JSON object only
        result = run(**kwargs)
    _record_stop(result, stop)
    summary = nulls(dataclasses.asdict(result)) if dataclasses.is_dataclass(result) else {}
    summary.update(ok=bool(result.ok), exit_code=result.exit_code, summary=str(result))
    if stop is not None:
        summary["stop_model"] = stop
    _print_json(summary)
    return result.exit_code


def _record_stop(result, stop) -> None:
    """The stop model a scene ran on (``--stop``) next to its bag: ``stop_model.json``
    (the bag's readers take its .mcap alone; docs/recording.md)."""
    bag = getattr(result, "bag_dir", None)
    if stop is not None and bag and os.path.isdir(bag):
        with open(os.path.join(bag, "stop_model.json"), "w", encoding="utf-8") as fh:
            json.dump(stop, fh, allow_nan=False, indent=1)


def cmd_demo(args):
    from pathlib import Path

    from grazing_control.studies.demo import main as demo_main

    if not args.json:
        return demo_main(args)
    with _stdout_to_stderr():  # the progress lines go to stderr
        status = demo_main(args)
    report = Path(args.out) / "report.json"
    summary = {"exit_code": status, "report": str(Path(args.out) / "report.md"),
               "numbers": str(report)}
    if report.is_file():
        summary.update(json.loads(report.read_text(encoding="utf-8")))
    _print_json(nulls(summary))
    return status


def _print_json(obj):
    json.dump(obj, sys.stdout, allow_nan=False)
    sys.stdout.write("\n")
    sys.stdout.flush()


# ---------------------------------------------------------------------------- parser
def build_parser() -> argparse.ArgumentParser:
    from grazing_control import __version__

    parser = _Parser(
        prog="grazing",
        description="Exact analysis and discrete control of grazing in an impact oscillator.")
    parser.add_argument("--version", action="version", version=f"grazing {__version__}")
    sub = parser.add_subparsers(dest="command", required=True)

    s = sub.add_parser("design", help="gains (c1, c2) for degenerate grazing, admissible c2")
    add_common(s)
    s.add_argument("--c2", type=finite, help="chosen gain c2 (or --optimize)")
    add_delay(s)
    s.add_argument("--delta-d", type=finite,
                   help="report the noise gain (std of the Pi2 position per unit measurement "
                        "noise) of the controlled orbit at this Delta d < 0; with --model the "
                        "predicted spread of every coordinate and of the corrections, with the "
                        "pulse and through the actuator (default the model file's Delta d "
                        "where < 0; docs/theory_ndof.md section 17)")
    s.add_argument("--sensor-rate", type=integer_at_least(2), default=200,
                   help="position-only sensor for the noise gain: samples per period "
                        "(default 200; with --model the wall coordinate's position)")
    s.add_argument("--estimator", choices=("model", "arc", "nearest"), default="model",
                   help="its Pi2 estimator (default model, docs/theory_estimation.md)")
    s.add_argument("--sensor-lead", type=non_negative, default=0.0,
                   help="its estimate made this long (model time) before the section's last "
                        "sample, the later samples unused (a rig controller's answer_lead; "
                        "default 0)")
    s.add_argument("--optimize", choices=("noise",),
                   help="choose c2 in the admissible set: noise = least noise gain at --delta-d "
                        "(default -5e-6, the study's first scene)")
    s.add_argument("--out", type=file_path, help="write the controller's YAML parameter file here "
                                             "(c1, c2, actuation_delay, X**, the model)")
    s.add_argument("--pulse-width", type=finite, default=0.0,
                   help="the correction as a force pulse of this width centred at --delay "
                        "(simulation time; sim_node's pulse_width); with it c1 is the exact "
                        "design for the pulse's force profile (P1, docs/theory_pulse.md); with "
                        "--model the n-DOF pulse design (docs/theory_ndof.md section 15)")
    s.add_argument("--actuator-bandwidth", type=finite, default=0.0,
                   help="a first-order actuator's bandwidth 1/tau_a (radians per simulation "
                        "time unit, sim_node's actuator_bandwidth; 0: ideal): c1 for the "
                        "force through it, the loop's margin and predicted spread at "
                        "--delta-d (needs --pulse-width)")
    s.add_argument("--actuator-latency", type=finite, default=0.0,
                   help="the actuator's latency (simulation time, sim_node's "
                        "actuator_latency; needs --pulse-width)")
    add_method(s)
    model_file.add_model_option(s)
    model_file.add_design_options(s)
    s.set_defaults(func=cmd_design)

    s = sub.add_parser("orbit", help="the 1/1 orbit and its Floquet multipliers")
    add_common(s)
    s.add_argument("--delta-d", type=finite, help="Delta d = d - d* (< 0); required unless "
                                                  "--rig or --params gives it")
    add_gains(s)
    add_method(s)
    model_file.add_model_option(s)
    model_file.add_gain_options(s, markov=True)
    model_file.add_pulse_option(s)
    s.set_defaults(func=cmd_orbit)

    s = sub.add_parser("continue", help="continue the 1/1 branch in Delta d, find bifurcations")
    add_common(s)
    s.add_argument("--from", dest="start", type=finite, required=True, help="start Delta d <= 0")
    s.add_argument("--to", dest="stop", type=finite, required=True, help="end Delta d <= 0")
    s.add_argument("--points", type=count, default=200,
                   help="grid points (default 200): values of Delta d log-spaced in |Delta d| "
                        "from --from to --to (--to 0: down to 1e-12 |--from|), the same with "
                        "or without --model")
    add_gains(s)
    model_file.add_model_option(s)
    model_file.add_gain_options(s, markov=True)
    model_file.add_pulse_option(s)
    s.set_defaults(func=cmd_continue)

    from .continue2 import add_parser as add_continue2_parser
    add_continue2_parser(sub, add_common, add_gains)

    s = sub.add_parser("simulate", help="simulate on Pi2, optionally switching control on")
    add_common(s)
    s.add_argument("--delta-d", type=finite, help="Delta d = d - d*; required unless --rig "
                                                  "or --params gives it")
    s.add_argument("--periods", type=count, required=True, help="number of forcing periods")
    s.add_argument("--control-after", type=count, help="switch control on at this sample")
    s.add_argument("--x0", type=finite, help="initial x on Pi2 (default x**)")
    s.add_argument("--v0", type=finite, help="initial v on Pi2 (default v**)")
    s.add_argument("--dx0", type=finite,
                   help="initial x - x** on Pi2 (deviation; full precision near grazing)")
    s.add_argument("--dv0", type=finite, help="initial v - v** on Pi2 (deviation)")
    s.add_argument("--lyapunov", action="store_true",
                   help="also the Lyapunov exponents per period over the last half of the "
                        "periods, with the sum identity (docs/theory_lyapunov.md)")
    s.add_argument("--fidelity", choices=("exact", "zdm2", "zdm1", "ode", "auto"), default="exact",
                   help="model: exact flow (default), normal-form maps zdm2/zdm1, solve_ivp "
                        "(ode, comparison), or auto: the cheapest meeting --tol over the horizon")
    s.add_argument("--tol", type=finite, default=1e-9,
                   help="Pi2 error tolerance for --fidelity auto (default 1e-9)")
    add_stop_options(s)
    add_gains(s)
    model_file.add_model_option(s)
    model_file.add_gain_options(s)
    model_file.add_pulse_option(s)
    model_file.add_start_option(s)
    s.set_defaults(func=cmd_simulate)

    from grazing_control.studies.sweeps.cli import add_sweep_command

    s = add_sweep_command(sub, add_common, finite, count)
    model_file.add_sweep_options(s)
    s.set_defaults(func=model_file.dispatch(s.get_default("func"), cmd_sweep))
    from .basins import add_basins_parser

    add_basins_parser(sub)

    try:
        from .run_arguments import add_run_arguments
    except ImportError:  # pragma: no cover - the launcher lands with the ROS issue
        add_run_arguments = None
    if add_run_arguments is not None:
        s = sub.add_parser("run", help="run a scene through the real ROS 2 nodes")
        add_run_arguments(s)
        s.add_argument("--live", type=_live_port, default=None, metavar="PORT",
                       help="also start live_node: a Foxglove WebSocket server on PORT "
                            "(e.g. 8765) streaming the scene to Foxglove/Lichtblick "
                            "(docs/live.md)")
        s.add_argument("--json", action="store_true",
                       help="print one JSON summary object: ok, exit_code, each node's "
                            "exit status, reason (why a failed scene failed: the realtime "
                            "watchdog's trip, a refused feasibility check, a node that "
                            "failed; docs/nodes.md), sim_verdict (the simulator's summary, "
                            "watchdog trip and feasibility verdict); node output goes to "
                            "stderr")
        add_run_stop_options(s)
        add_params_option(s)
        s.set_defaults(func=cmd_run)

    from .bag import add_bag_parser
    add_bag_parser(sub)
    from .rig import add_rig_parser
    add_rig_parser(sub)
    from .identify import add_identify_parser
    add_identify_parser(sub)
    from .stop import add_stop_parser
    add_stop_parser(sub)
    from grazing_control.studies.robustness.cli import add_robustness_parser

    add_robustness_parser(sub, add_common, finite)
    from grazing_control.studies.figures.command import add_parser as add_figures_parser

    s = add_figures_parser(sub)
    model_file.add_figures_options(s)
    s.set_defaults(func=model_file.dispatch(s.get_default("func"), cmd_figures))

    s = sub.add_parser("demo", help="the main job: the study's two control scenes and a report")
    s.add_argument("--out", type=file_path, default="out/demo", help="report folder (default out/demo)")
    s.add_argument("--offline", action="store_true", help="through the core only, no ROS nodes")
    s.add_argument("--json", action="store_true",
                   help="print one JSON summary object (progress goes to stderr)")
    s.set_defaults(func=cmd_demo)

    from grazing_control.recordings import add_commands   # analyze, replay (docs/analysis.md)
    add_commands(sub)
    return parser



def _require_delta_d(args) -> None:
    """orbit and simulate need Delta d: from --delta-d, --rig or --params."""
    if args.command in ("orbit", "simulate") and args.delta_d is None:
        raise ParameterError(f"{args.command}: the following arguments are required: "
                             "--delta-d (or --rig FILE, or --params FILE with delta_d)")


def _one_line(exc) -> str:
    return " ".join(str(exc).split()) or type(exc).__name__


@functools.lru_cache(maxsize=1)
def _parser() -> argparse.ArgumentParser:
    """:func:`build_parser`'s parser, built once a process (26 ms on a slow host): a
    parse does not change it, and in-process callers (the tests) call :func:`main`
    thousands of times."""
    return build_parser()


def main(argv=None) -> int:
    """Entry point of the `grazing` console script."""
    parser = _parser()
    argv = sys.argv[1:] if argv is None else list(argv)
    args = parser.parse_args(argv)
    try:
        # overflow in a computation shows up as nan/inf in the result, which is refused
        # below with one line; numpy's warnings would add lines of their own
        with warnings.catch_warnings(), np.errstate(all="ignore"):
            warnings.simplefilter("ignore", RuntimeWarning)
            model_file.check_options(args, argv)   # --model and the 1-DOF options
            apply_rig(args, argv)         # --rig FILE (cli/rig.py)
            apply_to_args(args, argv)     # --params FILE (cli/parameter_file.py)
            _require_delta_d(args)
            result = args.func(args)
    except (ParameterError, ValueError, RuntimeError, OSError) as exc:
        print(f"grazing: error: {_one_line(exc)}", file=sys.stderr)
        return 2
    except ArithmeticError as exc:  # ZeroDivisionError, OverflowError, FloatingPointError
        print(f"grazing: error: numerical failure ({type(exc).__name__}: {_one_line(exc)}): "
              "an input is outside the computable range", file=sys.stderr)
        return 2
    except MemoryError:
        print("grazing: error: out of memory: reduce the size of the request", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("grazing: interrupted", file=sys.stderr)
        return 130
    if isinstance(result, int):
        return result
    bad = non_finite(result) if isinstance(result, dict) else []
    if bad:
        print(f"grazing: error: {args.command}: the result is not finite ({', '.join(bad[:3])}): "
              "an input is outside the computable range", file=sys.stderr)
        return 2
    try:
        if isinstance(result, dict):
            json.dump(result, sys.stdout, allow_nan=False)
            sys.stdout.write("\n")
        elif result is not None:
            print(result)
        sys.stdout.flush()
    except BrokenPipeError:  # the reader went away (| head): not an error of ours
        sys.stdout = None
    return 0


if __name__ == "__main__":  # pragma: no cover
    sys.exit(main())
