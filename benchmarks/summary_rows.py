"""One row of the benchmark summary, and how its figures are printed."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class Headline:
    """One figure: ``ok`` is True / False against ``target``, None when only reported."""

    benchmark: str
    figure: str
    value: str
    target: str = ""
    paper: str = ""
    ok: bool | None = None


def fmt(x: Any, nd: int = 3, unit: str = "") -> str:
    if x is None:
        return "-"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return f"{x:,}{unit}"
    if isinstance(x, float):
        return f"{x:.{nd}g}{unit}" if abs(x) < 1e4 else f"{x:,.0f}{unit}"
    return str(x)
