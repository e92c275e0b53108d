"""What a panel is, and figures.md: each panel's caption and the numbers read off its data.

A :class:`Panel` carries the files written for it, what it shows, and the
:class:`Number` s computed from the same arrays that were drawn, each next to the
study's value where the study states one (spec section 8, issue 10 §3).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

__all__ = ["Number", "Panel", "render_markdown", "numbers_dict"]


@dataclass(frozen=True)
class Number:
    """One number read off a panel's data.

    key : machine name (figures.json); label : what it is; value : this run's value;
    study : the study's value (None where the study states none); fmt : format spec
    for floats; note : how it was obtained.
    """

    key: str
    label: str
    value: object
    study: object = None
    fmt: str = ".6g"
    note: str = ""

    def text(self, which: str = "value") -> str:
        return _fmt(getattr(self, which), self.fmt)


@dataclass(frozen=True)
class Panel:
    """A panel of the study's figures: name ('fig1a'), title, caption, files, numbers."""

    name: str
    title: str
    caption: str
    files: tuple
    numbers: tuple = field(default=())
    seconds: float = 0.0


def _fmt(value, fmt):
    if value is None:
        return "—"
    if isinstance(value, bool):
        return "yes" if value else "no"
    if isinstance(value, float):
        if math.isnan(value):
            return "nan"
        return format(value, fmt)
    if isinstance(value, (tuple, list)):
        return "(" + ", ".join(_fmt(v, fmt) for v in value) + ")"
    return str(value)


def _json_value(value):
    if isinstance(value, (tuple, list)):
        return [_json_value(v) for v in value]
    if isinstance(value, float) and not math.isfinite(value):
        return str(value)
    return value


def numbers_dict(panels) -> dict:
    """{panel name: {key: value}} (JSON-serialisable), the numbers of figures.md."""
    return {p.name: {n.key: _json_value(n.value) for n in p.numbers} for p in panels}


def render_markdown(panels, header: str, footer: str = "", image_prefix: str = "",
                    files: bool = True) -> str:
    """figures.md: per panel its image, its caption and a table of its numbers.

    ``image_prefix`` is put before each image's file name (docs/figures.md links the
    thumbnails in img/figures/); ``files`` lists the files written for each panel.
    """
    lines = [header.rstrip(), ""]
    for p in panels:
        png = next(f for f in p.files if f.endswith(".png"))
        lines += [f"## {p.name[3:]}: {p.title}", "", f"![{p.name}]({image_prefix}{png})", "",
                  p.caption, ""]
        if p.numbers:
            lines += ["| quantity | this run | study | how |", "|---|---|---|---|"]
            for n in p.numbers:
                cells = (n.label, n.text(), n.text("study"), n.note)
                lines.append("| " + " | ".join(c.replace("|", "\\|") for c in cells) + " |")
            lines.append("")
        others = [f for f in p.files if f != png]
        if files:
            lines += [f"Files: {', '.join([png] + others)} ({p.seconds:.1f} s).", ""]
    if footer:
        lines += [footer.rstrip(), ""]
    return "\n".join(lines)
