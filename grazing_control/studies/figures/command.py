"""`grazing figures`: the study's Figs. 1 and 2 into a folder (see :mod:`.build`)."""

from __future__ import annotations

from grazing_control.support.arguments import integer_at_least, non_empty_path

__all__ = ["add_parser", "run"]


_path = non_empty_path
_workers = integer_at_least(1)


def add_parser(sub):
    """Register the ``figures`` subcommand on an argparse subparsers object."""
    s = sub.add_parser("figures",
                       help="the study's Figs. 1 and 2: panels (PNG, SVG) and figures.md")
    s.add_argument("--out", type=_path, default="out/figures",
                   help="output folder (default out/figures)")
    s.add_argument("--quick", action="store_true",
                   help="coarse grids (seconds): every panel, lower resolution")
    s.add_argument("--bags", type=_path,
                   help="folder with the demo's recordings (scene_5e-6, scene_9e-6) for "
                        "Figs. 2(f, g); default: simulate the scenes")
    s.add_argument("--workers", type=_workers,
                   help="processes for the brute-force sweeps (default: all cores), >= 1")
    s.add_argument("--docs", type=_path,
                   help="also write DOCS/figures.md with thumbnails in DOCS/img/figures "
                        "(the repository's docs/)")
    s.add_argument("--json", action="store_true", help="print the numbers as one JSON object")
    s.set_defaults(func=run)
    return s


def run(args):
    import json
    import sys
    from pathlib import Path

    from grazing_control.oscillator.params import ParameterError
    from .build import FULL, QUICK, make_figures

    out = Path(args.out)
    if out.exists() and not out.is_dir():
        raise ParameterError(f"--out={args.out!r} is invalid: it exists and is not a folder")
    log = None if args.json else (lambda line: print(line, file=sys.stderr))
    make_figures(out, QUICK if args.quick else FULL, bags=args.bags, workers=args.workers,
                 progress=not args.json and sys.stderr.isatty(), log=log, docs=args.docs)
    doc = json.loads((out / "figures.json").read_text(encoding="utf-8"))
    if args.json:
        return doc
    return f"figures: {out / 'figures.md'}"
