"""The frame-transfer column smear (controller.vision.fisheye.smear): read far from the glare,
kept only when it is one, taken off the rim's samples."""

import math

import numpy as np
import pytest

from benchmarks import fisheye_third as third
from controller.calibration.fisheye_bundle import fisheye_bundle_from_dict
from controller.vision.fisheye import FisheyeEstimator, FisheyeOptions
from controller.vision.fisheye.blobs import find_blobs
from controller.vision.fisheye.glare import GlareOptions
from controller.vision.fisheye.lens import FisheyeLens
from controller.vision.fisheye.smear import column_smear
from controller.vision.fisheye.sphere import sample_sphere, tangent_basis

H, W, R_CIRCLE = 240, 320, 115.0  # a small frame, its image circle inside the height


def _frame(sun=(160.0, 120.0), smear=0.0, rng=None, cloud=None):
    """A grey frame: a sky sloping across the image circle, black outside it, a saturated
    glare of radius 6 px with a soft rim, and ``smear`` grey levels added to the whole of
    the columns the saturated core crosses, before the clip."""
    rng = rng or np.random.default_rng(1)
    v, u = np.mgrid[0:H, 0:W].astype(float)
    cx, cy = (W - 1) / 2, (H - 1) / 2
    inside = np.hypot(u - cx, v - cy) <= R_CIRCLE
    img = np.where(inside, 60.0 + 0.2 * (u - cx) + 0.1 * (v - cy), 0.0)
    d = np.hypot(u - sun[0], v - sun[1])
    img += 400.0 * np.clip(1.0 - (d - 6.0) / 6.0, 0.0, 1.0) ** 2 + 80.0 * np.exp(-d / 25.0)
    if cloud is not None:  # a bright band over some rows on one side only
        img[cloud] += 40.0
    img[:, np.abs(np.arange(W) - sun[0]) <= 6.0] += smear
    img += np.where(img > 0, rng.normal(0.0, 1.0, img.shape), 0.0)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def _smear_of(grey):
    peak = float(grey.max())
    return column_smear(grey, find_blobs(grey, peak - 4, None), peak)


def test_a_column_smear_is_read_in_its_columns_at_its_level():
    s = _smear_of(_frame(smear=10.0))
    assert s is not None
    cols = np.abs(np.arange(W) - 160.0) <= 6.0
    assert np.abs(s[cols] - 10.0).max() < 0.6
    assert np.abs(s[~cols]).max() < 0.6


def test_no_smear_reads_as_none():
    assert _smear_of(_frame(smear=0.0)) is None


def test_a_bright_band_on_one_side_of_the_glare_is_no_smear():
    """A cloud over the glare's columns in rows above it, not below: the two groups of rows
    disagree, and nothing is taken off."""
    assert _smear_of(_frame(smear=0.0, cloud=np.s_[10:60, 150:171])) is None


def test_near_the_edge_of_the_circle_one_side_of_the_rows_is_enough():
    """A low sun near the frame's bottom: no rows below it, the rows above (sky, and black
    outside the circle) are read as their nearer and further halves."""
    s = _smear_of(_frame(sun=(160.0, 222.0), smear=10.0))
    assert s is not None
    assert abs(float(s[160]) - 10.0) < 0.6


@pytest.mark.parametrize(
    ("pixel", "hidden", "want"), [(100, 20.0, 70.0), (255, 50.0, 255.0), (255, 20.0, None)]
)
def test_samples_lose_the_smear_under_the_clip_and_are_unknown_where_it_hides_the_rim(pixel, hidden, want):
    """Under the clip the level comes off; at the clip the pixel's light is unknown: left as
    it is where the smear is shallower than the rim's depth (``hidden``), NaN where not."""
    look = third.LOOKS[0]
    cam = fisheye_bundle_from_dict(third.bundle_dict(look)).camera
    lens = FisheyeLens.from_camera(cam)
    grey = np.full((look.height, look.width), 100, np.uint8)
    grey[int(cam.cy) - 3 : int(cam.cy) + 4, int(cam.cx) - 3 : int(cam.cx) + 4] = pixel
    level = np.zeros(look.width, np.float32)
    level[int(cam.cx) - 10 : int(cam.cx) + 11] = 30.0
    a = np.array([0.0, 0.0, 1.0])  # the optical axis: the principal point
    e1, e2 = tangent_basis(a)
    ((vals, _),) = sample_sphere(
        grey, lens, a, e1, e2, None, [(np.zeros(1), np.zeros(1))], (level, 251.0, hidden)
    )
    if want is None:
        assert np.isnan(vals).all()
    else:
        assert vals[0, 0] == pytest.approx(want)
    ((plain, _),) = sample_sphere(grey, lens, a, e1, e2, None, [(np.zeros(1), np.zeros(1))])
    assert plain[0, 0] == pytest.approx(pixel)


@pytest.mark.parametrize("t", [1774017600.0, 1774033200.0], ids=["20 Mar, morning", "20 Mar, afternoon"])
def test_the_third_renderers_smear_no_longer_moves_the_fix(t, monkeypatch):
    """The third renderer's 44.7-deg suns of 20 Mar (docs/fisheye-rounds.md, a seventeenth
    round): its smear moved the fix 0.060 and 0.072 deg from the same frame rendered without
    it (the same noise); with the smear taken off, within 0.01."""
    look = third.LOOKS[0]
    scene = third.ThirdScene(look)
    (_, az, el), *_ = [f for f in third.sun_frames("2026-03-20", 20) if f[0] == t]
    fixes = []
    for smear in (third.SMEAR, 0.0):
        monkeypatch.setattr(third, "SMEAR", smear)
        rng = np.random.default_rng([look.width, look.height, int(t)])
        img = scene.render(third.sun_enu(az, el), rng)
        opts = FisheyeOptions(glare=GlareOptions(column_smear=True))
        est = FisheyeEstimator(fisheye_bundle_from_dict(third.bundle_dict(look)), opts)
        r = est.estimate_image(img, t)
        assert r.found
        fixes.append(third.sun_enu(r.az_deg, r.el_deg))
    assert math.degrees(math.acos(min(1.0, float(fixes[0] @ fixes[1])))) < 0.01


def test_a_glare_whose_rim_the_smeared_clip_hides_is_measured_with_the_smear_left_in(monkeypatch):
    from controller.vision.fisheye import smear as sm

    calls = []

    def fake_fit(grey, lens, x, y, r, peak, opts, *, up_cam=None, radiometry=None, smear=None):
        calls.append(smear is not None)
        return None if smear is not None else "fit"

    monkeypatch.setattr(sm, "fit_glare", fake_fit)
    level = np.ones(4, np.float32)
    assert sm.fit_smeared(np.zeros((2, 4), np.uint8), None, (1.0, 1.0, 1.0), 255.0, None, level) == "fit"
    assert calls == [True, False]
    calls.clear()
    assert sm.fit_smeared(np.zeros((2, 4), np.uint8), None, (1.0, 1.0, 1.0), 255.0, None, None) == "fit"
    assert calls == [False]
