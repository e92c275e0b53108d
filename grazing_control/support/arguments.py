"""Argument types shared by the `grazing` subcommands: one-line errors naming the range.

argparse turns the :class:`argparse.ArgumentTypeError` raised here into
``grazing: error: <command>: argument --name: '<text>' is invalid: ...`` (status 2).
"""

from __future__ import annotations

import argparse
import math

__all__ = ["finite", "positive", "negative", "integer_at_least", "non_empty_path"]


def finite(text: str) -> float:
    """A finite real number."""
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: expected a finite real number")
    return value


def positive(text: str) -> float:
    """A finite real number > 0."""
    value = finite(text)
    if not value > 0.0:
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: expected a finite number > 0")
    return value


def non_negative(text: str) -> float:
    """A finite real number >= 0."""
    value = finite(text)
    if not value >= 0.0:
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: expected a finite number >= 0")
    return value


def negative(text: str) -> float:
    """A finite real number < 0 (a wall offset Delta d on the impacting side)."""
    value = finite(text)
    if not value < 0.0:
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: expected a finite number < 0")
    return value


def integer_at_least(minimum: int):
    """The type of an integer option >= ``minimum``."""
    def parse(text: str) -> int:
        try:
            value = int(text)
        except ValueError:
            value = None
        if value is None or value < minimum:
            raise argparse.ArgumentTypeError(
                f"{text!r} is invalid: expected an integer >= {minimum}")
        return value

    parse.__name__ = f"integer_at_least_{minimum}"
    return parse


def non_empty_path(text: str) -> str:
    """A path that is not empty (nor only blanks)."""
    if not text.strip():
        raise argparse.ArgumentTypeError(f"{text!r} is invalid: expected a non-empty path")
    return text
