"""What a simulated run covers: its start, its cycles, and the truth's days and samples."""

from __future__ import annotations

from dataclasses import dataclass
from datetime import UTC, date, datetime, timedelta

import numpy as np

from controller.config import Config
from controller.errors import ConfigError

from .scenario import as_scenario

__all__ = [
    "MAX_DAYS",
    "Span",
    "checked_length",
    "cycles_per_day",
    "day_samples",
    "day_start",
    "simulation_span",
]

#: The longest run ``simulate`` accepts (days): about ten years.
MAX_DAYS = 3660


def checked_length(days: int | None, hours: float | None) -> tuple[int, float | None]:
    """A run's length as the command line gives it: whole ``days`` (1 when neither is given)
    or ``hours``, not both (``--hours`` had won silently over ``--days``)."""
    if days is not None and hours is not None:
        raise ConfigError(None, "--days", "--days or --hours, not both", f"--days {days} --hours {hours:g}")
    if days is not None and not 1 <= days <= MAX_DAYS:
        raise ConfigError(None, "--days", f"a whole number of days in [1, {MAX_DAYS}]", days)
    if hours is not None and not 0 < hours <= 24 * 366:
        raise ConfigError(None, "--hours", "a number of hours in (0, 8784]", hours)
    return (1 if days is None else days), hours


def day_start(d: date, longitude: float) -> float:
    """POSIX time of local mean midnight starting day ``d`` at this longitude."""
    midnight_utc = datetime(d.year, d.month, d.day, tzinfo=UTC)
    return (midnight_utc - timedelta(hours=longitude / 15.0)).timestamp()


@dataclass(frozen=True)
class Span:
    """What a run covers: its first cycle (POSIX s), its number of cycles and how its start
    is shown (a date, or an ISO time)."""

    t0: float
    n_cycles: int
    label: str


def simulation_span(
    config: Config, days: int = 1, start: date | datetime | None = None, hours: float | None = None
) -> Span:
    """``days`` whole days from local mean midnight of ``start`` (a date), or from an aware
    datetime; ``hours`` instead of days when given."""
    scenario = as_scenario(config)
    if not 1 <= days <= MAX_DAYS:
        raise ConfigError(None, "--days", f"a whole number of days in [1, {MAX_DAYS}]", days)
    first = start or scenario.hil.start
    t0 = first.timestamp() if isinstance(first, datetime) else day_start(first, scenario.site.longitude)
    seconds = days * 86400 if hours is None else hours * 3600
    n = max(1, round(seconds / scenario.control.period_s))
    return Span(t0, n, first.isoformat())


def cycles_per_day(period_s: float) -> int:
    """Cycles in one stretch of truth (a day, to the nearest whole cycle)."""
    return max(1, round(86400 / period_s))


def day_samples(span: Span, period_s: float, substeps: int, day: int) -> tuple[np.ndarray, np.ndarray]:
    """The cycle times of day ``day`` of a run, and its truth sample times (``substeps``
    per cycle, at the middles of equal parts of the period)."""
    per_day = cycles_per_day(period_s)
    i0 = day * per_day
    i1 = min(span.n_cycles, i0 + per_day)
    cycles = span.t0 + np.arange(i0, i1) * period_s
    offsets = (np.arange(substeps) + 0.5) / substeps * period_s
    return cycles, (cycles[:, None] + offsets[None, :]).ravel()
