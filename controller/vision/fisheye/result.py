"""The fisheye sensor's per-frame result, shared by the seed and the default pipelines."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...sun.types import SunObservation


@dataclass
class FisheyeResult:
    """One frame's outcome.

    Attributes
    ----------
    image : str or None
        The file it came from (None for an in-memory image).
    found : bool
        True when the sun was measured; otherwise ``reason`` says why not.
    time : float or None
        POSIX seconds (UTC) of the frame.
    frame : str
        ``"enu"`` when the bundle has an orientation; else ``"model"``: az/el of the
        camera-frame vector read as if the camera axes (x, y, z) were (East, North, Up).
    az_deg, el_deg : float or None
        Sun direction (deg; azimuth clockwise from north, elevation above the horizon).
    sigma_deg : float or None
        One-sigma angular uncertainty (deg).
    d_cam : ndarray or None
        Unit sun vector in the camera frame (OpenCV axes).
    centre_uv : (u, v) or None
        The sun's centre in the image (px; the projection of ``d_cam``).
    offset_px : (dh, da) or None
        The paper's offsets of the sun from the image centre (px): ``dh = U - W/2`` (the
        paper's altitude axis), ``da = V - H/2`` (its azimuth axis).
    offset_deg : (ax, ay) or None
        Angular offsets of the sun from the optical axis about the camera's axes (deg):
        ``atan2(x, z)`` and ``atan2(y, z)`` of ``d_cam``; zero when the camera looks at it.
    radius_deg : float or None
        Angular radius of the saturated glare disk (deg).
    quality : tuple of str
        Flags (``several_candidates``, ``smear``, ``outliers_rejected``, ...).
    """

    image: str | None
    found: bool
    reason: str | None = None
    time: float | None = None
    frame: str = "model"
    algorithm: str = "default"
    az_deg: float | None = None
    el_deg: float | None = None
    sigma_deg: float | None = None
    d_cam: np.ndarray | None = None
    centre_uv: tuple[float, float] | None = None
    offset_px: tuple[float, float] | None = None
    offset_deg: tuple[float, float] | None = None
    radius_deg: float | None = None
    quality: tuple[str, ...] = ()
    extra: dict = field(default_factory=dict)

    def observation(self) -> SunObservation | None:
        """The measurement for the sun-path filter, or None when nothing was found."""
        if not self.found or self.time is None or self.az_deg is None or self.el_deg is None:
            return None
        return SunObservation(
            time=float(self.time),
            az_deg=float(self.az_deg),
            el_deg=float(self.el_deg),
            sigma_deg=float(self.sigma_deg or 0.3),
            frame=self.frame,
            quality=tuple(self.quality),
            sensor="fisheye",
        )

    def to_json(self) -> dict:
        """One JSON-ready line: ``image``, ``found``, ``reason`` (when not found), ``az_deg``,
        ``el_deg``, ``quality``, ...; numbers rounded to what they mean."""
        d: dict = {"image": self.image, "found": self.found}
        if not self.found:
            d["reason"] = self.reason
        if self.time is not None:
            d["time"] = self.time
        d.update(
            {
                "algorithm": self.algorithm,
                "frame": self.frame,
                "az_deg": _r(self.az_deg),
                "el_deg": _r(self.el_deg),
                "sigma_deg": _r(self.sigma_deg),
                "quality": list(self.quality),
            }
        )
        if self.centre_uv is not None:
            d["centre_uv"] = [_r(self.centre_uv[0], 3), _r(self.centre_uv[1], 3)]
        if self.offset_px is not None:
            d["offset_px"] = [_r(self.offset_px[0], 3), _r(self.offset_px[1], 3)]
        if self.offset_deg is not None:
            d["offset_deg"] = [_r(self.offset_deg[0]), _r(self.offset_deg[1])]
        if self.radius_deg is not None:
            d["radius_deg"] = _r(self.radius_deg, 3)
        d.update(self.extra)
        return d


def _r(x, nd: int = 5):
    return None if x is None else round(float(x), nd)


def not_found(
    image: str | None, reason: str, t: float | None, frame: str, algorithm: str, **extra
) -> FisheyeResult:
    return FisheyeResult(
        image=image,
        found=False,
        reason=reason,
        time=t,
        frame=frame,
        algorithm=algorithm,
        quality=(reason,),
        extra=dict(extra),
    )
