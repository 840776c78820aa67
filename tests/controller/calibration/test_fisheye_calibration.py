"""The fisheye bundle, the lens calibration, the orientation from the sun and the horizon."""

import math

import numpy as np
import pytest

from controller.calibration.fisheye_bundle import (
    FisheyeBundle,
    fisheye_bundle_from_dict,
    load_fisheye_bundle,
    save_fisheye_bundle,
)
from controller.calibration.fisheye_lens import calibrate_fisheye
from controller.calibration.fisheye_orientation import (
    check_plausible,
    fit_orientation,
    kabsch,
    level_from_horizon,
    sun_vectors,
)
from controller.errors import ConfigError, InputError
from controller.sun.source import Site
from hil.skycam import render_sky, seed_lens
from hil.skycam.checkerboard import checkerboard_poses, render_checkerboard
from tests.controller.vision.fisheye.helpers import small_scene, truth_bundle, utc

DOC = {
    "camera": {
        "model": "fisheye",
        "width": 640,
        "height": 480,
        "fx": 166.0,
        "fy": 166.0,
        "cx": 319.5,
        "cy": 239.5,
        "dist": [-0.042, 0.001, -0.0005, 0.0],
    },
    "orientation": {"enu_from_camera": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]},
    "site": {"latitude": 32.5, "longitude": 48.3},
}


def rot_deg(A, B) -> float:
    return math.degrees(math.acos(np.clip((np.trace(A @ B.T) - 1) / 2, -1, 1)))


def test_bundle_round_trip(tmp_path):
    b = fisheye_bundle_from_dict(DOC)
    p = save_fisheye_bundle(b, tmp_path / "sky.toml")
    again = load_fisheye_bundle(p)
    assert again.camera == b.camera and again.site == b.site
    np.testing.assert_allclose(again.enu_from_camera, np.eye(3))
    assert 'model = "fisheye"' in p.read_text()
    assert "sky_scale" not in p.read_text()  # 1, the default, is not written
    scaled = {**DOC, "orientation": {**DOC["orientation"], "sky_scale": 1.85}}
    again = load_fisheye_bundle(save_fisheye_bundle(fisheye_bundle_from_dict(scaled), tmp_path / "s.toml"))
    assert again.orientation.sky_scale == 1.85
    assert again.orientation.sky_calibration is None  # a bundle with the scale alone: as before
    assert "sky_calibration" not in p.read_text()
    four = {**DOC, "orientation": {**DOC["orientation"], "sky_calibration": [1.9, -0.15, 2.6, -0.2]}}
    p4 = save_fisheye_bundle(fisheye_bundle_from_dict(four), tmp_path / "c.toml")
    assert "sky_calibration = [1.9, -0.15, 2.6, -0.2]" in p4.read_text()
    again = load_fisheye_bundle(p4)
    assert again.orientation.sky_calibration == (1.9, -0.15, 2.6, -0.2)
    assert again.orientation.sky_scale == 1.0
    assert again.orientation.locator is None and "locator" not in p4.read_text()
    rings = {**DOC, "orientation": {**DOC["orientation"], "locator": "rings"}}
    p5 = save_fisheye_bundle(fisheye_bundle_from_dict(rings), tmp_path / "r.toml")
    assert 'locator = "rings"' in p5.read_text()
    assert load_fisheye_bundle(p5).orientation.locator == "rings"


@pytest.mark.parametrize(
    "patch, key",
    [
        ({"camera": {**DOC["camera"], "model": "pinhole", "dist": [0, 0, 0, 0, 0]}}, "camera.model"),
        ({"camera": {**DOC["camera"], "dist": [0.1, 0.2]}}, "camera.dist"),
        (
            {"orientation": {"enu_from_camera": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}},
            "orientation.enu_from_camera",
        ),
        (
            {"orientation": {"enu_from_camera": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "locator": "ring"}},
            "orientation.locator",
        ),
        (
            {"orientation": {"enu_from_camera": [[2, 0, 0], [0, 1, 0], [0, 0, 1]]}},
            "orientation.enu_from_camera",
        ),
        ({"site": {"latitude": 123.0, "longitude": 0.0}}, "site.latitude"),
        ({"extra": 1}, "extra"),
        (
            {"orientation": {"enu_from_camera": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "typo": 3}},
            "orientation.typo",
        ),
        (
            {"orientation": {"enu_from_camera": [[1, 0, 0], [0, 1, 0], [0, 0, 1]], "sky_scale": 5.0}},
            "orientation.sky_scale",
        ),
        (
            {
                "orientation": {
                    "enu_from_camera": [[1, 0, 0], [0, 1, 0], [0, 0, 1]],
                    "sky_calibration": [2, 0],
                }
            },
            "orientation.sky_calibration",
        ),
        ({"radiometry": {"response": "cubic"}}, "radiometry.response"),
        ({"radiometry": {"response": "gamma"}}, "radiometry.gamma"),
        ({"radiometry": {"response": "gamma", "gamma": 0.5}}, "radiometry.gamma"),
        ({"radiometry": {"response": "srgb", "gamma": 2.2}}, "radiometry.gamma"),
        ({"radiometry": {"response": "table", "table": [0.0, 1.0]}}, "radiometry.table"),
        (
            {"radiometry": {"response": "table", "table": [1.0 - i / 255 for i in range(256)]}},
            "radiometry.table",
        ),
        ({"radiometry": {"response": "linear", "table": [i / 255 for i in range(256)]}}, "radiometry.table"),
        ({"radiometry": {"vignetting": [-1.0]}}, "radiometry.vignetting"),
        ({"radiometry": {"vignetting": [0.0, 0.0, 0.0, 0.0, 0.1]}}, "radiometry.vignetting"),
        ({"camera": {**DOC["camera"], "cx": 5000.0}}, "camera.cx"),
        ({"camera": {**DOC["camera"], "cy": -3.0}}, "camera.cy"),
        ({"mount": {"panel_from_camera": [[1, 0, 0], [0, 1, 0], [0, 0, -1]]}}, "mount.panel_from_camera"),
        ({"mount": {"panel_from_camera": [[1, 0, 0], [0, 1, 0]]}}, "mount.panel_from_camera"),
        ({"mount": {"panel_from_camera": [[1, 0, 0], [0, 1, 0], [0, 0, 1]]}}, "mount"),
    ],
)
def test_bundle_errors_name_the_key(patch, key):
    with pytest.raises(ConfigError) as exc:
        fisheye_bundle_from_dict({**DOC, **patch})
    assert exc.value.key == key


def test_a_panel_cameras_mount_round_trips(tmp_path):
    c, sn = math.cos(math.radians(0.8)), math.sin(math.radians(0.8))
    M = [[c, 0.0, sn], [0.0, 1.0, 0.0], [-sn, 0.0, c]]
    doc = {"camera": DOC["camera"], "mount": {"panel_from_camera": M, "residual_deg": 0.03, "frames": 31}}
    p = save_fisheye_bundle(fisheye_bundle_from_dict(doc), tmp_path / "panel.toml")
    again = load_fisheye_bundle(p)
    np.testing.assert_allclose(again.mount.matrix, M, atol=1e-12)
    assert (again.mount.residual_deg, again.mount.frames) == (0.03, 31)
    assert (
        load_fisheye_bundle(save_fisheye_bundle(fisheye_bundle_from_dict(DOC), tmp_path / "s.toml")).mount
        is None
    )


def test_dist_as_opencv_returns_it_is_taken():
    """``D.tolist()`` of cv2.fisheye.calibrate is 4 x 1; it had been refused (an audit)."""
    D = np.array([[-0.042], [0.001], [-0.0005], [0.0]])
    b = fisheye_bundle_from_dict({**DOC, "camera": {**DOC["camera"], "dist": D.tolist()}})
    assert b.camera.dist == (-0.042, 0.001, -0.0005, 0.0)


def test_radiometry_round_trip(tmp_path):
    table = [(i / 255) ** 2.2 for i in range(256)]
    for rad in (
        {"response": "srgb", "vignetting": [-0.115, 0.0095, -0.0003]},
        {"response": "gamma", "gamma": 2.2},
        {"response": "table", "table": table, "method": "debevec, 7 frames"},
    ):
        b = fisheye_bundle_from_dict({**DOC, "radiometry": rad})
        again = load_fisheye_bundle(save_fisheye_bundle(b, tmp_path / "sky.toml"))
        assert again.radiometry == b.radiometry
    assert fisheye_bundle_from_dict(DOC).radiometry is None


def test_a_nearly_orthonormal_matrix_is_tidied():
    R = np.eye(3) + 1e-5 * np.arange(9).reshape(3, 3)
    b = fisheye_bundle_from_dict({**DOC, "orientation": {"enu_from_camera": R.tolist()}})
    M = b.enu_from_camera
    np.testing.assert_allclose(M.T @ M, np.eye(3), atol=1e-12)


def test_lens_calibration_from_rendered_boards():
    lens = seed_lens()
    rng = np.random.default_rng(7)
    views = [
        (f"b{i}", render_checkerboard(lens, rv, tv, rng=rng))
        for i, (rv, tv) in enumerate(checkerboard_poses(lens, 20, rng, max_theta_deg=75))
    ]
    views.append(("blank", np.zeros((480, 640), np.uint8)))
    res = calibrate_fisheye(views, (640, 480))
    assert res.rms_px < 0.15 and "blank" in res.rejected
    cam = res.camera
    assert cam.model == "fisheye"
    assert cam.fx == pytest.approx(166.0, abs=0.8) and cam.cx == pytest.approx(319.5, abs=0.5)
    with pytest.raises(InputError):
        calibrate_fisheye(views[:3], (640, 480))


def test_kabsch_recovers_a_rotation():
    rng = np.random.default_rng(0)
    R = np.linalg.qr(rng.normal(size=(3, 3)))[0]
    R *= np.sign(np.linalg.det(R))
    d = rng.normal(size=(20, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    np.testing.assert_allclose(kabsch(d, d @ R.T), R, atol=1e-12)


def test_orientation_from_a_day_of_sun_vectors_rejects_a_distractor():
    scn = small_scene()
    site = Site(latitude=scn.site.latitude, longitude=scn.site.longitude, altitude=scn.site.altitude)
    ts = utc(2025, 3, 20, 4, 0) + np.arange(0, 9 * 3600, 900.0)
    s = sun_vectors(site, ts)
    R_true = scn.R_enu_from_cam
    rng = np.random.default_rng(1)
    d = s @ R_true + rng.normal(0, np.radians(0.02), s.shape)  # camera frame, 0.02 deg noise
    d[5] = np.array([0.3, 0.1, 0.95])  # a reflection taken for the sun
    fit = fit_orientation(ts, d, site, refine=None)
    assert fit.rejected >= 1 and fit.residual_deg < 0.05
    assert rot_deg(fit.enu_from_camera, R_true) < 0.02
    assert fit.tilt_deg == pytest.approx(0.8, abs=0.02)


def test_orientation_refined_on_pixels_from_rendered_frames():
    scn = small_scene()
    b = truth_bundle(scn, orientation=False, site=False)
    from controller.vision.fisheye import FisheyeEstimator

    est = FisheyeEstimator(b)
    ts, dirs, uvs = [], [], []
    for t in utc(2025, 6, 21, 3, 0) + np.arange(0, 10 * 3600, 1800.0):
        r = est.estimate_image(render_sky(scn, t).image, t)
        if r.found:
            ts.append(t)
            dirs.append(r.d_cam)
            uvs.append(r.centre_uv)
    site = Site(latitude=scn.site.latitude, longitude=scn.site.longitude, altitude=scn.site.altitude)
    fit = fit_orientation(ts, np.array(dirs), site, uv=np.array(uvs), camera=b.camera, refine="rotation")
    assert len(ts) >= 15 and fit.residual_px < 0.3
    assert rot_deg(fit.enu_from_camera, scn.R_enu_from_cam) < 0.05


def test_a_mirrored_day_leaves_its_pixel_residual_and_is_refused():
    """Frames written bottom-up: no rotation fits.  The pixel refinement had turned the
    whole day behind the lens, where a sun had cost nothing (0 px), and the bundle was
    written with the camera looking 29 deg below the horizon."""
    from controller.vision.fisheye.lens import FisheyeLens

    scn = small_scene()
    b = truth_bundle(scn, orientation=False, site=False)
    site = Site(latitude=scn.site.latitude, longitude=scn.site.longitude, altitude=scn.site.altitude)
    ts = utc(2025, 6, 21, 3, 0) + np.arange(0, 10 * 3600, 900.0)  # not an equinox's great circle
    lens = FisheyeLens.from_camera(b.camera)
    uv, ok = lens.project(sun_vectors(site, ts) @ scn.R_enu_from_cam)
    assert ok.all()
    uv[:, 1] = b.camera.height - 1 - uv[:, 1]  # mirrored top to bottom
    d, ok = lens.rays(uv)
    fit = fit_orientation(ts, d, site, uv=uv, camera=b.camera, refine="rotation")
    assert fit.residual_deg > 5.0 and fit.residual_px > 10.0, (fit.residual_deg, fit.residual_px)
    with pytest.raises(InputError, match="mirrored"):
        check_plausible(fit)
    # Started from a rotation that puts the whole day behind the lens, the refinement must
    # not stay there: a sun the lens cannot image is not a perfect fit.
    from controller.calibration.fisheye_orientation import _refine

    flip = np.diag([1.0, -1.0, -1.0])  # the camera turned upside down
    R, _, px = _refine(scn.R_enu_from_cam @ flip, uv, sun_vectors(site, ts), b.camera, "rotation", None, 0.1)
    assert px > 10.0


def test_a_horizon_a_tenth_of_a_degree_off_does_not_pull_a_day_of_the_sun():
    """Terrain and an arc cut by the frame put a tilted camera's horizon zenith 0.17 deg off
    (an audit); trusted to 0.1 deg it had pulled the day's rotation 0.12 deg off."""
    from controller.vision.fisheye.lens import FisheyeLens

    scn = small_scene()
    b = truth_bundle(scn, orientation=False, site=False)
    site = Site(latitude=scn.site.latitude, longitude=scn.site.longitude, altitude=scn.site.altitude)
    ts = utc(2025, 6, 21, 3, 0) + np.arange(0, 10 * 3600, 1200.0)
    lens = FisheyeLens.from_camera(b.camera)
    uv, ok = lens.project(sun_vectors(site, ts) @ scn.R_enu_from_cam)
    uv += np.random.default_rng(3).normal(0, 0.03, uv.shape)
    d, _ = lens.rays(uv)
    zen = scn.R_enu_from_cam.T @ np.array([0.0, 0.0, 1.0])
    tip = np.cross(zen, [1.0, 0.0, 0.0])
    off = zen + math.radians(0.2) * tip / np.linalg.norm(tip)  # the horizon's zenith, 0.2 deg off
    fit = fit_orientation(ts, d, site, uv=uv, camera=b.camera, refine="rotation", horizon_zenith_cam=off)
    assert rot_deg(fit.enu_from_camera, scn.R_enu_from_cam) < 0.03
    assert fit.horizon_disagreement_deg == pytest.approx(0.2, abs=0.03)  # still reported


def test_an_orientation_a_sky_camera_cannot_have_is_refused():
    """A wrong latitude sign fits a day of the sun as well as the right one, with the
    camera turned over on its side."""
    scn = small_scene()
    site = Site(latitude=scn.site.latitude, longitude=scn.site.longitude, altitude=scn.site.altitude)
    ts = utc(2025, 3, 20, 4, 0) + np.arange(0, 9 * 3600, 900.0)
    d = sun_vectors(site, ts) @ scn.R_enu_from_cam
    right = fit_orientation(ts, d, site, refine=None)
    check_plausible(right)
    wrong = fit_orientation(ts, d, Site(latitude=-site.latitude, longitude=site.longitude), refine=None)
    assert wrong.residual_deg < 0.1 and wrong.tilt_deg > 50.0  # a good fit of a wrong camera
    with pytest.raises(InputError, match="wrong --lat sign"):
        check_plausible(wrong)
    check_plausible(wrong, max_tilt_deg=90.0)  # a camera said to be tilted that much


def test_level_from_the_horizon():
    scn = small_scene()
    fr = render_sky(scn, utc(2025, 3, 20, 8, 0))
    lv = level_from_horizon(fr.image, truth_bundle(scn).camera)
    z_true = scn.R_enu_from_cam.T @ np.array([0.0, 0.0, 1.0])
    assert math.degrees(math.acos(float(lv.zenith_cam @ z_true))) < 0.2
    assert lv.points > 100 and lv.tilt_deg == pytest.approx(0.8, abs=0.2)
    with pytest.raises(InputError):
        level_from_horizon(np.zeros_like(fr.image), truth_bundle(scn).camera)


def test_an_untouched_bundle_type_is_frozen():
    b = fisheye_bundle_from_dict(DOC)
    assert isinstance(b, FisheyeBundle)
    with pytest.raises(AttributeError):
        b.site = None  # type: ignore[misc]


@pytest.mark.parametrize(
    "drop, message", [("model", "without the key a camera is a pinhole one"), ("dist", "is the key missing?")]
)
def test_a_missing_lens_key_is_not_reported_as_the_pinholes_default(drop, message):
    camera = {k: v for k, v in DOC["camera"].items() if k != drop}
    with pytest.raises(ConfigError) as exc:
        fisheye_bundle_from_dict({**DOC, "camera": camera})
    assert message in str(exc.value)


def test_a_mask_that_hides_the_whole_sky_is_refused(tmp_path):
    import cv2

    from controller.vision.fisheye.frames import load_mask

    w, h = DOC["camera"]["width"], DOC["camera"]["height"]
    cv2.imwrite(str(tmp_path / "black.png"), np.zeros((h, w), np.uint8))
    bundle = fisheye_bundle_from_dict({**DOC, "mask": "black.png"}, tmp_path / "b.toml")
    with pytest.raises(ConfigError) as exc:
        load_mask(bundle, (h, w))
    assert exc.value.key == "mask" and "leaves some of the sky in" in str(exc.value)
