import subprocess
import sys

import cv2
import numpy as np
import pytest

from hil.camera import CameraModel, checkerboard_poses, profile, render_checkerboard, render_frame
from hil.errors import HilError
from tests.controller.vision.helpers import small_scenario, utc


def test_hil_camera_does_not_import_the_controller():
    code = "import sys, hil.camera, hil.camera.render; print(any(m.startswith('controller') for m in sys.modules))"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_glint_is_brightest_at_the_mirror_point():
    scn = small_scenario(noise=False)
    for t in (utc(2025, 3, 20, 5, 0), utc(2025, 3, 20, 9, 0)):
        fr = render_frame(scn, t)
        u, v = fr.truth["glint_uv"]
        img = fr.image.astype(float)
        sat = np.argwhere(img >= 250)
        assert len(sat) > 0
        cy, cx = sat.mean(0)
        assert abs(cx - u) < 1.0 and abs(cy - v) < 1.0


def test_truth_sun_is_pvlib_and_model_frame_is_consistent():
    scn = small_scenario()
    tr = render_frame(scn, utc(2025, 6, 21, 9, 0)).truth
    np.testing.assert_allclose(scn.R_model_to_enu @ tr["sun_model"], tr["sun_enu"], atol=1e-12)
    assert 60 < tr["el_deg"] < 90  # Andimeshk near noon at the solstice


def test_clouds_dim_the_glint_and_exposure_saturates():
    scn = small_scenario(noise=False)
    t = utc(2025, 6, 21, 6, 0)
    clear = render_frame(scn, t).image
    cloud = render_frame(scn, t, transmittance=0.05).image
    over = render_frame(scn, t, exposure_factor=50).image
    assert clear.max() == 255 and cloud.max() < 230
    assert (over == 255).sum() > 20 * (clear == 255).sum()


def test_bad_requests_raise_hil_errors():
    with pytest.raises(HilError):
        profile("nope")
    with pytest.raises(HilError):
        render_frame(small_scenario(), utc(2025, 6, 21, 6, 0), transmittance=1.5)


def test_noise_is_reproducible_and_unbiased():
    scn = small_scenario(noise=True)
    t = utc(2025, 6, 21, 6, 0)
    a = render_frame(scn, t, rng=np.random.default_rng(5)).image
    b = render_frame(scn, t, rng=np.random.default_rng(5)).image
    c = render_frame(scn.with_(sensor=scn.sensor.__class__(noise=False)), t).image
    assert np.array_equal(a, b)
    d = a.astype(float) - c
    assert abs(d[(c > 20) & (c < 200)].mean()) < 0.5 and d.std() > 0.3


def test_checkerboard_corners_are_subpixel_exact():
    cam = CameraModel(400, 300, 330.0, 330.0, 199.5, 149.5, (-0.1, 0.02, 0, 0, 0))
    rng = np.random.default_rng(2)
    ((rvec, tvec),) = checkerboard_poses(cam, 1, rng)
    img = render_checkerboard(cam, rvec, tvec, rng=rng, noise_dn=0.0)
    ok, corners = cv2.findChessboardCorners(img, (9, 6))
    assert ok
    corners = cv2.cornerSubPix(
        img, corners, (5, 5), (-1, -1), (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_COUNT, 100, 1e-4)
    )
    obj = np.zeros((54, 3))
    obj[:, :2] = (np.mgrid[0:9, 0:6].T.reshape(-1, 2) + 1) * 0.04
    truth = cam.project(obj, rvec, tvec)
    c = corners.reshape(-1, 2)
    err = np.linalg.norm(c[:, None, :] - truth[None], axis=2).min(axis=1)  # order-free match
    assert np.median(err) < 0.1 and err.max() < 0.3
