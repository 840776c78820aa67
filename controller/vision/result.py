"""The hotspot sensor's answer for one frame."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..sun.types import SunObservation


@dataclass
class HotspotResult:
    image: str | None
    found: bool
    reason: str | None = None
    time: float | None = None
    frame: str = "model"
    az_deg: float | None = None
    el_deg: float | None = None
    sigma_deg: float | None = None
    s_model: np.ndarray | None = None
    s_enu: np.ndarray | None = None
    quality: tuple[str, ...] = ()
    area_px: int = 0
    centre_uv: tuple[float, float] | None = None
    model_az_deg: float | None = None
    model_el_deg: float | None = None
    extra: dict = field(default_factory=dict)

    def observation(self) -> SunObservation | None:
        if (
            not self.found
            or self.time is None
            or self.az_deg is None
            or self.el_deg is None
            or self.sigma_deg is None
        ):
            return None
        return SunObservation(
            time=float(self.time),
            az_deg=float(self.az_deg),
            el_deg=float(self.el_deg),
            sigma_deg=float(self.sigma_deg),
            frame=self.frame,
            quality=tuple(self.quality),
            sensor="hotspot",
        )

    def to_json(self) -> dict[str, Any]:
        d: dict[str, Any] = {"image": self.image, "found": self.found}
        if not self.found:
            d["reason"] = self.reason
        if self.time is not None:
            d["time"] = self.time
        d.update(
            {
                "frame": self.frame,
                "az_deg": rounded(self.az_deg),
                "el_deg": rounded(self.el_deg),
                "sigma_deg": rounded(self.sigma_deg),
                "quality": list(self.quality),
                "area_px": self.area_px,
            }
        )
        if self.centre_uv is not None:
            d["centre_uv"] = [rounded(self.centre_uv[0], 3), rounded(self.centre_uv[1], 3)]
        if self.s_model is not None:
            d["model_az_deg"] = rounded(self.model_az_deg)
            d["model_el_deg"] = rounded(self.model_el_deg)
        d.update(self.extra)
        return d


def rounded(x: float | None, nd: int = 5) -> float | None:
    return None if x is None else round(float(x), nd)
