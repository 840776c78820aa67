"""Procedural drifting clouds on a layer at a fixed height, with an optical depth.

A periodic fractal noise texture (power spectrum ~ k^-beta) is laid on a horizontal plane
``height_m`` above the camera and advected with the wind.  The optical depth is

    tau = tau_max (1 - exp(-max(n - n_c, 0) / edge))

where ``n`` is the texture (zero mean, unit variance) and ``n_c`` its ``1 - coverage``
quantile: the cloud cores are thick and the edges thin.  A view sees

    L = exp(-tau) L_behind + (1 - exp(-tau)) L_diffuse(tau) + F p(chi) tau exp(-tau) T_dim

the sky behind, the cloud's own diffuse light (greyer when thick), and sunlight scattered
forward by the cloud (Henyey-Greenstein phase ``p``, g = 0.85, normalised to 1 at chi = 0),
which makes thin edges near the sun shine and saturate (the "silver lining").  The sun's
beam is dimmed by ``exp(-tau)`` sampled on its own line of sight.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import lru_cache

import cv2
import numpy as np

TEX = 512


@dataclass(frozen=True)
class CloudField:
    """A cloud layer.  ``coverage`` 0..1 (fraction of the layer that is cloud), ``tau_max``
    optical depth of the cores, ``height_m`` of the layer, ``wind_mps`` = (east, north)
    drift, ``scale_m`` typical cloud size, ``edge`` softness of the edges (noise units),
    ``forward`` strength of the forward-scattered sunlight (full scale at chi = 0, tau = 1)."""

    coverage: float = 0.4
    tau_max: float = 12.0
    height_m: float = 1500.0
    wind_mps: tuple[float, float] = (8.0, 3.0)
    scale_m: float = 900.0
    edge: float = 0.35
    forward: float = 10.0
    seed: int = 1
    beta: float = 3.0

    @property
    def cell_m(self) -> float:
        return self.scale_m / 10.0

    def threshold(self) -> float:
        """The texture level above which there is cloud."""
        return _threshold(self.seed, self.beta, float(np.clip(self.coverage, 0.0, 1.0)))


@lru_cache(maxsize=8)
def _texture(seed: int, beta: float) -> np.ndarray:
    rng = np.random.default_rng(seed)
    k = np.fft.fftfreq(TEX)
    kk = np.hypot(k[:, None], k[None, :])
    kk[0, 0] = 1.0
    # fractal within a band: nothing larger than ~4 cloud sizes (10 texels per cloud size)
    amp = kk ** (-beta / 2.0) * (1.0 - np.exp(-((kk * 40.0) ** 2)))
    amp[0, 0] = 0.0
    amp[kk > 0.25] *= np.exp(-(((kk[kk > 0.25] - 0.25) / 0.05) ** 2))  # no texel-scale aliasing
    spec = amp * (rng.standard_normal((TEX, TEX)) + 1j * rng.standard_normal((TEX, TEX)))
    tex = np.real(np.fft.ifft2(spec))
    tex = (tex - tex.mean()) / tex.std()
    out = tex.astype(np.float32)
    out.setflags(write=False)
    return out


@lru_cache(maxsize=8)
def _blurred(seed: int, beta: float) -> tuple[np.ndarray, np.ndarray]:
    """Two pre-filtered copies of the texture (sigma 2 and 6 texels) for far views."""
    spec = np.fft.fft2(_texture(seed, beta))
    k = np.fft.fftfreq(TEX)
    k2 = k[:, None] ** 2 + k[None, :] ** 2
    out = tuple(
        np.real(np.fft.ifft2(spec * np.exp(-2.0 * np.pi**2 * s * s * k2))).astype(np.float32)
        for s in (2.0, 6.0)
    )  # periodic Gaussian blur
    for a in out:
        a.setflags(write=False)
    return out  # type: ignore[return-value]


@lru_cache(maxsize=64)
def _threshold(seed: int, beta: float, coverage: float) -> float:
    return float(np.quantile(_texture(seed, beta), 1.0 - coverage))


def optical_depth(field: CloudField, dirs_enu: np.ndarray, t: float, pixel_rad: float = 0.0) -> np.ndarray:
    """Optical depth along ENU unit directions (N, 3) at POSIX time ``t`` (0 below ~0.5 deg).

    ``pixel_rad``: the angular size of a pixel; far views (whose pixel covers several
    texels of the layer) read pre-filtered textures instead of aliasing.
    """
    d = np.asarray(dirs_enu, np.float32).reshape(-1, 3)
    up = d[:, 2]
    ok = up > np.sin(np.radians(0.5))
    s = np.where(ok, field.height_m / np.maximum(up, 1e-3), 0.0)
    x = s * d[:, 0] - field.wind_mps[0] * (t % 1e6)
    y = s * d[:, 1] - field.wind_mps[1] * (t % 1e6)
    # OpenCV's remap takes maps of at most 32767 per side: lay the samples out in rows
    n_pts = d.shape[0]
    cols = 1024
    rows = -(-n_pts // cols)
    mx = np.zeros(rows * cols, np.float32)
    my = np.zeros(rows * cols, np.float32)
    mx[:n_pts] = np.mod(x / field.cell_m, TEX)
    my[:n_pts] = np.mod(-y / field.cell_m, TEX)
    tex = _texture(field.seed, field.beta)
    mxr, myr = mx.reshape(rows, cols), my.reshape(rows, cols)

    def sample(img):
        return cv2.remap(img, mxr, myr, cv2.INTER_LINEAR, borderMode=cv2.BORDER_WRAP).ravel()[:n_pts]

    n = sample(tex)
    if pixel_rad > 0:
        fp = s * pixel_rad / np.maximum(up, 0.05) / field.cell_m  # footprint in texels
        if np.any(fp > 1.0):
            b1, b2 = _blurred(field.seed, field.beta)
            w1 = np.clip((fp - 1.0) / 3.0, 0.0, 1.0)
            w2 = np.clip((fp - 4.0) / 8.0, 0.0, 1.0)
            n = (1 - w1) * n + w1 * ((1 - w2) * sample(b1) + w2 * sample(b2))
    tau = field.tau_max * (1.0 - np.exp(-np.maximum(n - field.threshold(), 0.0) / field.edge))
    fade = np.clip((np.degrees(np.arcsin(np.clip(up, -1, 1))) - 0.5) / 2.5, 0.0, 1.0)
    return (tau * fade * ok).astype(np.float32)


def hg_ratio(chi: np.ndarray, g: float = 0.85) -> np.ndarray:
    """Henyey-Greenstein phase function at angle ``chi`` (rad) divided by its value at 0."""
    denom = (1.0 + g * g - 2.0 * g * np.cos(chi)) ** 1.5
    return ((1.0 - g) ** 3 / denom).astype(np.float32)


def cloud_radiance(
    field: CloudField, tau: np.ndarray, L_behind: np.ndarray, chi: np.ndarray, sun_dim: float, level: float
) -> np.ndarray:
    """Radiance (N, 3) of views with optical depth ``tau`` in front of ``L_behind`` (N, 3).

    ``chi``: angle to the sun (rad); ``sun_dim``: the sun's beam transmittance from the air
    mass times its own cloud transmittance reaching the layer (1 = full sun); ``level``: the
    sky's brightness scale (the auto-exposed zenith level).
    """
    a = np.exp(-tau)[:, None]
    diffuse = (level * (2.3 - 1.2 * (1.0 - np.exp(-tau / 5.0))))[:, None]
    fwd = field.forward * hg_ratio(chi) * tau * np.exp(-tau) * sun_dim
    warm = np.array([1.0, 0.98, 0.94], np.float32)
    return (a * L_behind + (1.0 - a) * diffuse + fwd[:, None] * warm).astype(np.float32)
