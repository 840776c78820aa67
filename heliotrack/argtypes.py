"""Checked number types for command-line options: a NaN, an infinity or a value out of
its physical range is refused by argparse in one line (exit 2) before any work is done."""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable


def number_in(lo: float, hi: float, *, open_lo: bool = False) -> Callable[[str], float]:
    """An argparse ``type``: a finite float in ``[lo, hi]`` (``(lo, hi]`` with ``open_lo``)."""
    left = "(" if open_lo else "["

    def convert(text: str) -> float:
        try:
            x = float(text)
        except ValueError:
            x = math.nan
        if not (math.isfinite(x) and (x > lo if open_lo else x >= lo) and x <= hi):
            raise argparse.ArgumentTypeError(f"expected a number in {left}{lo:g}, {hi:g}], got {text!r}")
        return x

    convert.__name__ = "number"  # argparse names the type in some messages
    return convert


def int_in(lo: int, hi: int) -> Callable[[str], int]:
    """An argparse ``type``: an integer in ``[lo, hi]``."""

    def convert(text: str) -> int:
        try:
            n = int(text)
        except ValueError:
            n = lo - 1
        if not lo <= n <= hi:
            raise argparse.ArgumentTypeError(f"expected an integer in [{lo}, {hi}], got {text!r}")
        return n

    convert.__name__ = "integer"
    return convert


def board_pattern(text: str) -> tuple[int, int]:
    """An argparse ``type``: a checkerboard's inner corners ``NxM`` (each 2-100)."""
    try:
        nx, ny = (int(x) for x in text.lower().split("x"))
    except ValueError:
        nx = ny = 0
    if not (2 <= nx <= 100 and 2 <= ny <= 100):
        raise argparse.ArgumentTypeError(f"expected inner corners like 9x6 (each 2-100), got {text!r}")
    return nx, ny


LATITUDE = number_in(-90.0, 90.0)
LONGITUDE = number_in(-180.0, 180.0)
ALTITUDE = number_in(-500.0, 9000.0)
#: A checkerboard's square, metres (a millimetre to a metre).
SQUARE_M = number_in(0.0, 1.0, open_lo=True)
