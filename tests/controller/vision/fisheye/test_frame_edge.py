"""Frames unlike the renderer's own: an image circle cut by the sensor, a diffraction star."""

import math
from dataclasses import replace

import numpy as np
import pytest

from benchmarks.fisheye_suites import result_error
from controller.vision.fisheye import FisheyeEstimator
from hil.skycam import render_sky, sky_profile
from hil.skycam.lens import full_hd_lens
from hil.skycam.scene import orientation

from .helpers import truth_bundle, utc


def test_a_sun_cut_by_the_frames_edge_is_refused_not_misplaced():
    """A 1920 x 1080 sensor behind a lens whose sky circle is wider than the frame is high
    (the 90-deg circle at ~700 px), turned so that the morning sun comes in over the top
    edge (21 Jun 2026 at the seed site).  While its centre is outside the frame or its glare
    (26 px in radius) is cut, no fix is reported; once the centre is 21 px inside it is
    found within 0.05 deg.  The bundle keeps the rim, as calibrating this renderer's camera
    chooses (docs/fisheye.md, "Locator"): a camera with no choice starts halfway to its
    rings, up to 0.1 deg off here, which is not this test's subject."""
    scn = sky_profile("seed", noise=True)
    lens = replace(full_hd_lens(), fx=510.0, fy=510.0, name="cropped")
    scn = scn.with_(lens=lens, enu_from_camera=orientation(yaw_deg=90.0))
    bundle = truth_bundle(scn)
    assert bundle.orientation is not None
    est = FisheyeEstimator(replace(bundle, orientation=replace(bundle.orientation, locator="rim")))
    for hour, inside in ((3.5, False), (3.9, False), (4.05, True), (4.3, True)):
        t = utc(2026, 6, 21) + hour * 3600.0
        fr = render_sky(scn, t)
        res = est.estimate_image(fr.image, t)
        v = fr.truth["sun_uv"][1]
        if inside:
            assert res.found and result_error(res, fr.truth) < 0.05, (hour, v, res.reason)
        else:
            assert not res.found, f"found {result_error(res, fr.truth):.2f} deg off, centre at v = {v:.0f}"
            assert res.reason in ("no_sun_glare", "no_rim", "incomplete_glare"), res.reason


def _with_star(
    img: np.ndarray, uv, spikes: int, r_px: float, amp: float, width_px: float = 1.2
) -> np.ndarray:
    """``spikes`` diffraction spikes from ``uv`` (px), ``amp`` grey levels at ``r_px`` from
    it and falling as 1 / r outside, Gaussian across (``width_px``)."""
    H, W = img.shape[:2]
    yy, xx = np.mgrid[0:H, 0:W].astype(np.float32)
    dx, dy = xx - uv[0], yy - uv[1]
    r = np.hypot(dx, dy) + 1e-3
    th = np.arctan2(dy, dx)
    add = np.zeros((H, W), np.float32)
    for k in range(spikes):
        d = np.abs(np.angle(np.exp(1j * (th - 0.3 - 2.0 * math.pi * k / spikes))))
        across = r * np.sin(np.minimum(d, math.pi / 2))
        add += amp * np.exp(-0.5 * (across / width_px) ** 2) * (d < math.pi / 2) * np.minimum(1.0, r_px / r)
    return np.clip(img.astype(np.float32) + add[..., None], 0, 255).round().astype(np.uint8)


@pytest.mark.parametrize("hour", [7.0, 9.0, 12.0])
def test_a_six_pointed_diffraction_star_leaves_the_sun_where_it_is(hour):
    """A star of six spikes, 120 grey levels over the glare at its rim: on the rays they
    cross, the rim lies up to half a radius further out, and the robust fit leaves those
    rays out (20 Mar 2026, 35-57 deg: 0.023-0.034 deg, against 0.005-0.007 without the
    star; with every ray kept the fit is refused as ``irregular_glare``)."""
    scn = sky_profile("seed", noise=True)
    est = FisheyeEstimator(truth_bundle(scn))
    t = utc(2026, 3, 20) + hour * 3600.0
    fr = render_sky(scn, t)
    r_px = fr.truth["glare_radius_deg"] / est.lens.deg_per_px(*fr.truth["sun_uv"])
    res = est.estimate_image(_with_star(fr.image, fr.truth["sun_uv"], 6, r_px, 120.0), t)
    assert res.found and result_error(res, fr.truth) < 0.06, res.reason
    assert "outliers_rejected" in res.quality
