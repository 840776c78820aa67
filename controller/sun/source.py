"""Sun sources: anything that tells the controller where the sun is at a given time.

A source returns a :class:`~controller.sun.types.SunEstimate` (or ``None`` when it has
nothing to say, e.g. a camera with no glint).  The first implementation is astronomical:
pvlib's SPA for the configured site.  Camera sensors and the sun-path filter plug in behind
the same interface.
"""

from __future__ import annotations

import abc
from dataclasses import dataclass
from datetime import UTC, datetime, timedelta, tzinfo
from typing import TYPE_CHECKING, Any
from zoneinfo import ZoneInfo, ZoneInfoNotFoundError

import numpy as np
import pandas as pd
import pvlib

from ..schema import Where, setting

if TYPE_CHECKING:
    from ..store import Store
from .types import EstimateSource, SunEstimate, SunObservation


@dataclass(frozen=True)
class Site:
    """Geographic site.  Latitude north-positive, longitude east-positive, degrees."""

    latitude: float = setting(doc="Latitude, north positive.", unit="deg", ge=-90, le=90)
    longitude: float = setting(doc="Longitude, east positive.", unit="deg", ge=-180, le=180)
    altitude: float = setting(0.0, doc="Height above sea level.", unit="m", ge=-500, le=9000)
    pressure_pa: float | None = setting(
        None,
        doc="Mean air pressure (none: from the altitude) for refraction.",
        unit="Pa",
        ge=30000,
        le=110000,
    )
    temperature_c: float = setting(
        12.0, doc="Mean air temperature, for refraction.", unit="degC", ge=-60, le=60
    )
    name: str = setting("", doc="Name (reports, SunSpec).")
    timezone: str = setting(
        "",
        doc="IANA time zone of the plant's civil clock, e.g. \"Europe/Oslo\", for SunSpec's "
        "local date and time (DtLoc, TmLoc, Day); empty: local mean solar time, UTC + "
        "longitude / 15 h. The controller itself runs on UTC either way.",
        example="Asia/Tehran",
    )

    def __schema_check__(self, at: Where) -> Site:
        if self.timezone:
            try:
                civil_zone(self.timezone)
            except ValueError:
                raise at.child("timezone").error(
                    'an IANA time zone name such as "Europe/Oslo" or "UTC"', self.timezone
                ) from None
        return self

    @property
    def pressure(self) -> float:
        if self.pressure_pa is not None:
            return self.pressure_pa
        return float(pvlib.atmosphere.alt2pres(self.altitude))


def civil_zone(name: str) -> tzinfo:
    """The IANA zone ``name`` (``[site] timezone``); ValueError when there is none by it."""
    try:
        return ZoneInfo(name)
    except (ZoneInfoNotFoundError, ValueError, TypeError, OSError) as exc:
        raise ValueError(f"no time zone {name!r}") from exc


def site_local_time(site: Site, t_posix: float) -> datetime:
    """The plant's local wall time at ``t_posix`` (naive): civil time in ``site.timezone``,
    else local mean solar time (UTC + longitude / 15 h)."""
    utc = datetime.fromtimestamp(t_posix, tz=UTC)
    if site.timezone:
        return utc.astimezone(civil_zone(site.timezone)).replace(tzinfo=None)
    return (utc + timedelta(hours=site.longitude / 15.0)).replace(tzinfo=None)


def solar_position(site: Site, times) -> pd.DataFrame:
    """pvlib SPA solar position for POSIX seconds or datetimes (UTC).

    Returns pvlib's frame: ``apparent_elevation`` (refraction-corrected, deg),
    ``azimuth`` (deg clockwise from north), ``apparent_zenith``, ...
    """
    idx = _to_index(times)
    return pvlib.solarposition.get_solarposition(
        idx,
        site.latitude,
        site.longitude,
        altitude=site.altitude,
        pressure=site.pressure,
        temperature=site.temperature_c,
        method="nrel_numpy",
    )


def _to_index(times) -> pd.DatetimeIndex:
    arr = np.atleast_1d(times)
    if arr.dtype.kind in "fiu":
        return pd.DatetimeIndex(pd.to_datetime(arr.astype(float), unit="s", utc=True))
    return pd.DatetimeIndex(pd.to_datetime(arr, utc=True))


class SunSource(abc.ABC):
    """Interface of every sun source."""

    name: str = "abstract"

    @abc.abstractmethod
    def estimate(self, t: float, now: float | None = None) -> SunEstimate | None:
        """Best estimate of the sun's direction at POSIX time ``t``, or None.

        ``now`` is the present when ``t`` is ahead of it (setpoints aim at mid-period).
        """

    def observe(self, obs: SunObservation) -> bool:
        """Take a sensor's observation; True when it was used.  Sources that learn nothing
        from observations (the ephemeris) ignore it."""
        return False

    def use_store(self, store: Store, now: float) -> None:  # noqa: B027 - stateless: nothing
        """Keep learned state in ``store`` from now on (loaded from it when it holds one);
        stateless sources ignore it."""

    def save(self) -> None:  # noqa: B027 - a no-op by design for stateless sources
        """Persist what the source has learned (atomically); a no-op for stateless sources."""

    def summary(self) -> dict[str, Any]:
        """What the source has learned, for reports (empty for stateless sources)."""
        return {}


class EphemerisSource(SunSource):
    """The sun from the ephemeris (pvlib SPA) at a known site: exact when the clock is right.

    Parameters
    ----------
    site : Site
    sigma_deg : float
        Reported one-sigma (deg); SPA itself is +-0.0003 deg, refraction near the horizon
        dominates the real uncertainty.
    """

    name = "ephemeris"

    def __init__(self, site: Site, sigma_deg: float = 0.01):
        self.site = site
        self.sigma_deg = sigma_deg

    def estimate(self, t: float, now: float | None = None) -> SunEstimate:
        sp = solar_position(self.site, [t]).iloc[0]
        s2 = self.sigma_deg**2
        return SunEstimate(
            time=float(t),
            az_deg=float(sp["azimuth"]),
            el_deg=float(sp["apparent_elevation"]),
            covariance=np.diag([s2, s2]),
            source=EstimateSource.EPHEMERIS,
        )
