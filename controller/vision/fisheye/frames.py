"""Reading and checking sky-camera frames: a bad file is a reason, never an exception.

Frames are colour (the seed pipeline needs hue and saturation); 8-bit BGR as OpenCV reads
them.  16-bit images are scaled to 8 bits, grey images are accepted as three equal
channels, an alpha channel is dropped.
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

import cv2
import numpy as np

from ...calibration.fisheye_bundle import FisheyeBundle, OrientationCal, SiteCal
from ...errors import ConfigError
from ..imageio import read_image, to_uint8

if TYPE_CHECKING:
    from .default import FisheyeOptions
    from .glare import GlareOptions


def load_frame(path: str | Path) -> tuple[np.ndarray | None, str | None]:
    """(BGR uint8 image, None) or (None, reason).

    The file is read by :func:`controller.vision.imageio.read_image` (reasons
    ``file_not_found``, ``unreadable_file``, ``empty_file``, ``truncated_file``,
    ``image_too_large``, ``undecodable_image``), then normalised by :func:`as_bgr8`.
    """
    img, reason = read_image(path)
    if img is None:
        return None, reason
    return as_bgr8(img)


def as_bgr8(img: np.ndarray | None) -> tuple[np.ndarray | None, str | None]:
    """Normalise an in-memory image to contiguous BGR uint8, or (None, reason); samples of
    other depths as :func:`controller.vision.imageio.to_uint8` reads them."""
    if img is None or not isinstance(img, np.ndarray) or img.size == 0:
        return None, "no_image"
    img, why = to_uint8(img)
    if img is None:
        return None, why
    if img.ndim == 2:
        img = cv2.cvtColor(img, cv2.COLOR_GRAY2BGR)
    elif img.ndim == 3 and img.shape[2] == 4:
        img = cv2.cvtColor(img, cv2.COLOR_BGRA2BGR)
    elif img.ndim == 3 and img.shape[2] == 1:
        img = cv2.cvtColor(img[:, :, 0], cv2.COLOR_GRAY2BGR)
    if img.ndim != 3 or img.shape[2] != 3:
        return None, "unsupported_image_format"
    return np.ascontiguousarray(img), None


def load_mask(bundle: FisheyeBundle, shape: tuple[int, int]) -> np.ndarray | None:
    """The bundle's mask (255 where the sky is seen), or None; a bad one is a ConfigError."""
    if bundle.mask is None:
        return None
    m = cv2.imread(str(bundle.mask), cv2.IMREAD_GRAYSCALE)
    if m is None or m.shape != shape:
        raise ConfigError(
            bundle.path, "mask", f"a readable {shape[1]}x{shape[0]} mask image", str(bundle.mask)
        )
    if not m.any():  # every frame would be `no_sun_glare`: a mask written inverted, or black
        raise ConfigError(
            bundle.path, "mask", "a mask that leaves some of the sky in (white = use)", str(bundle.mask)
        )
    return np.where(m > 0, 255, 0).astype(np.uint8)


def with_sky_scale(
    options: FisheyeOptions, orientation: OrientationCal | None, site: SiteCal | None = None
) -> FisheyeOptions:
    """``options`` (a :class:`.default.FisheyeOptions`) with the bundle orientation's
    ``sky_scale`` applied to its glare options (multiplying theirs) and its
    ``sky_calibration``, which was fitted on frames with their column smear taken off, with
    that removal (:mod:`.smear`).  With the ``site`` as well (its ephemeris gate on), the
    sky models leave a cloud's edge out of the rings (``GlareOptions.cloud_edges``): that
    reads suns under broken cloud closer, and accepts rims that the cloud's edge in the
    models had made irregular; without the gate, some of those are suns dimmed by the
    cloud and read 1-2 deg off (the third renderer's clouds without the site: 8 false
    detections where there had been 1).  With the site, a CCD's column smear is taken off
    too (:mod:`.smear`): the rings that may place the sun (:mod:`.rings`) read it as the sky's
    light (a third renderer's sun at 79 deg, 0.107 deg off by its rings with the smear in
    them), and its removal lets through fixes that only the ephemeris gate refuses (that
    renderer's clouds without the site: 4 false detections where there had been 1)."""
    if orientation is None:
        return options
    glare = options.glare
    if orientation.sky_scale != 1.0:
        glare = replace(glare, sky_scale=glare.sky_scale * orientation.sky_scale)
    if orientation.sky_calibration is not None:
        glare = replace(glare, sky_calibration=orientation.sky_calibration, column_smear=True)
    if site is not None and options.gates.ephemeris:
        glare = sited(glare)
    return options if glare is options.glare else replace(options, glare=glare)


def sited(glare: GlareOptions) -> GlareOptions:
    """``glare`` (:class:`.glare.GlareOptions`) as a camera measures once an ephemeris gate
    refuses a fix more than a degree off: a cloud's edge left out of the sky models, a CCD's
    column smear taken off (:func:`with_sky_scale` says why each waits for that gate).  A
    camera without the bundle's site measures so once it has learned the site from the sun
    (:mod:`.selfsite`; ``GateOptions.sited_once_learned``)."""
    return replace(glare, cloud_edges=True, column_smear=True)
