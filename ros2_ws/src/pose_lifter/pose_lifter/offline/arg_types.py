"""The ``argparse`` types of the command line's numbers: each parses an int or a finite float in a
range and names what is wrong in argparse's own message (exit 2, ``pose-lifter <cmd>: error:
argument ...``)."""

from __future__ import annotations

import argparse
import math
from typing import Any

__all__ = ["FINITE", "FRACTION", "NONNEG", "POSITIVE", "POS_INT", "number"]


def number(kind: type[int] | type[float], low: float | None = None, high: float | None = None,
            low_open: bool = False) -> Any:
    """An argparse ``type``: an int or a finite float in [low, high] (or (low, high] if low_open)."""
    def parse(text: str) -> int | float:
        try:
            value = kind(text)
        except ValueError:
            raise argparse.ArgumentTypeError(f"not a{'n integer' if kind is int else ' number'}: {text!r}") \
                from None
        if not math.isfinite(value):
            raise argparse.ArgumentTypeError(f"must be finite, got {text!r}")
        if low is not None and (value <= low if low_open else value < low):
            raise argparse.ArgumentTypeError(f"must be {'>' if low_open else '>='} {low:g}, got {text}")
        if high is not None and value > high:
            raise argparse.ArgumentTypeError(f"must be <= {high:g}, got {text}")
        return value
    parse.__name__ = kind.__name__  # argparse names the type in its messages
    return parse


POS_INT = number(int, 1)
NONNEG = number(float, 0.0)
POSITIVE = number(float, 0.0, low_open=True)
FRACTION = number(float, 0.0, 1.0)
FINITE = number(float)
