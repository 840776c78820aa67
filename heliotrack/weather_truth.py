"""The world's view of a weather stow: when the true gust crossed the threshold, and when
every drive was (really) in STOW mode and at its stow angle.

The controller only learns of the gust at its next anemometer poll; these times come from
the world's wind and the emulated drives, so they measure the whole chain.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from firmware_protocol import Mode
from hil.drive import DriveFirmware
from hil.wind import WindScript


@dataclass
class StormEpisode:
    """One storm: times in POSIX s (NaN until reached)."""

    alarm: float
    all_stow_mode: float = math.nan
    all_stowed: float = math.nan
    resumed: float = math.nan

    def as_dict(self) -> dict[str, float | None]:
        def s(x: float) -> float | None:
            return None if math.isnan(x) else round(x - self.alarm, 2)

        return {
            "alarm_utc_s": self.alarm,
            "stow_mode_after_s": s(self.all_stow_mode),
            "stowed_after_s": s(self.all_stowed),
            "resumed_after_s": s(self.resumed),
        }


@dataclass
class WeatherTruth:
    """Follows the true gust against the stow threshold and the drives' true modes."""

    wind: WindScript
    gust_stow_m_s: float
    episodes: list[StormEpisode] = field(default_factory=list)
    _above: bool = False

    def sample(self, t: float, firmwares: dict[str, DriveFirmware]) -> None:
        gust = self.wind.gust(t)
        above = gust >= self.gust_stow_m_s
        if (
            above
            and not self._above
            and (
                not self.episodes
                or not math.isnan(self.episodes[-1].resumed)
                or math.isnan(self.episodes[-1].all_stow_mode)
            )
        ):
            if not self.episodes or not math.isnan(self.episodes[-1].resumed):
                self.episodes.append(StormEpisode(alarm=self._crossing(t)))
        self._above = above
        if not self.episodes:
            return
        ep = self.episodes[-1]
        modes = [m for fw in firmwares.values() for m in fw.modes]
        if math.isnan(ep.all_stow_mode) and all(m == Mode.STOW for m in modes):
            ep.all_stow_mode = t
        if (
            math.isnan(ep.all_stowed)
            and all(m == Mode.STOW for m in modes)
            and all(ax.at_target for fw in firmwares.values() for ax in fw.axes)
        ):
            ep.all_stowed = t
        if not math.isnan(ep.all_stow_mode) and math.isnan(ep.resumed) and all(m == Mode.AUTO for m in modes):
            ep.resumed = t

    def _crossing(self, t: float, step: float = 1.0, lookback: float = 60.0) -> float:
        """The first second before ``t`` (within ``lookback``) at which the gust was above."""
        first = t
        s = t - step
        while s > t - lookback and self.wind.gust(s) >= self.gust_stow_m_s:
            first = s
            s -= step
        return first

    def summary(self) -> dict:
        eps = [e.as_dict() for e in self.episodes]
        worst = [e["stow_mode_after_s"] for e in eps if e["stow_mode_after_s"] is not None]
        worst_at = [e["stowed_after_s"] for e in eps if e["stowed_after_s"] is not None]
        return {
            "storms": len(eps),
            "episodes": eps,
            "stow_mode_worst_s": max(worst) if worst else None,
            "stowed_worst_s": max(worst_at) if worst_at else None,
        }
