"""The HIL sky camera: its own lens model, truth from pvlib, and what each effect does."""

import subprocess
import sys
from dataclasses import replace
from datetime import UTC, datetime

import cv2
import numpy as np
import pandas as pd
import pvlib
import pytest

from hil.errors import HilError
from hil.skycam import (
    AircraftGlint,
    CloudField,
    FisheyeLens,
    FlareGhost,
    GlareModel,
    SpecularReflection,
    orientation,
    render_sky,
    seed_lens,
    sky_profile,
)
from hil.skycam.checkerboard import board_corners, checkerboard_poses, render_checkerboard

T_MORNING = datetime(2025, 3, 20, 6, 0, tzinfo=UTC).timestamp()


def small(noise=False, **kw):
    """The seed camera at half the pixels per side (fast)."""
    scn = sky_profile("seed", noise=noise)
    return scn.with_(lens=scn.lens.scaled(0.5, "small"), **kw)


def test_hil_skycam_does_not_import_the_controller():
    code = (
        "import sys, hil.skycam, hil.skycam.render, hil.skycam.dataset; "
        "print(any(m.startswith('controller') for m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"


def test_lens_round_trip_beyond_ninety_degrees():
    lens = seed_lens()
    rng = np.random.default_rng(1)
    th = rng.uniform(0, np.radians(94), 500)
    ph = rng.uniform(-np.pi, np.pi, 500)
    d = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], 1)
    uv, ok = lens.project(d)
    back, ok2 = lens.unproject(uv)
    assert ok.all() and ok2.all()
    np.testing.assert_allclose(back, d, atol=1e-9)


def test_lens_agrees_with_opencv_in_front_of_the_lens():
    lens = seed_lens()
    th = np.radians(np.linspace(1, 85, 30))
    d = np.stack([np.sin(th) * 0.6, np.sin(th) * 0.8, np.cos(th)], 1)
    uv, _ = lens.project(d)
    ref, _ = cv2.fisheye.projectPoints(
        d.reshape(-1, 1, 3), np.zeros(3), np.zeros(3), lens.K, np.asarray(lens.D, float).reshape(4, 1)
    )
    np.testing.assert_allclose(uv, ref.reshape(-1, 2), atol=1e-6)


def test_a_lens_that_folds_back_is_refused():
    with pytest.raises(HilError):
        FisheyeLens(640, 480, 166, 166, 319.5, 239.5, D=(-0.5, 0.0, 0.0, 0.0), fov_deg=190)


def test_truth_is_pvlib_apparent_position_and_camera_frame_is_consistent():
    scn = small()
    fr = render_sky(scn, T_MORNING)
    tr = fr.truth
    sp = pvlib.solarposition.get_solarposition(
        pd.DatetimeIndex([pd.Timestamp(T_MORNING, unit="s", tz="UTC")]),
        scn.site.latitude,
        scn.site.longitude,
        altitude=scn.site.altitude,
    )
    assert tr["el_deg"] == pytest.approx(float(sp["apparent_elevation"].iloc[0]), abs=1e-9)
    assert tr["az_deg"] == pytest.approx(float(sp["azimuth"].iloc[0]), abs=1e-9)
    np.testing.assert_allclose(scn.R_enu_from_cam @ tr["sun_cam"], tr["sun_enu"], atol=1e-12)


def test_orientation_tips_the_optical_axis_towards_the_given_azimuth():
    R = np.asarray(orientation(tilt_deg=10.0, tilt_azimuth_deg=90.0))
    axis = R @ np.array([0.0, 0.0, 1.0])  # the optical axis in ENU
    assert axis[0] > 0 and abs(axis[1]) < 1e-12  # towards East
    assert np.degrees(np.arccos(axis[2])) == pytest.approx(10.0)


def test_the_sun_is_a_saturated_disk_centred_on_its_true_pixel():
    fr = render_sky(small(), T_MORNING)
    grey = cv2.cvtColor(fr.image, cv2.COLOR_BGR2GRAY)
    ys, xs = np.nonzero(grey >= 254)
    u, v = fr.truth["sun_uv"]
    assert len(xs) > 20
    assert abs(xs.mean() - u) < 0.7 and abs(ys.mean() - v) < 0.7
    # nothing is saturated far from the sun in a clear sky
    assert np.hypot(xs - u, ys - v).max() < 15


def test_the_glare_grows_with_exposure_and_shrinks_under_thin_cloud():
    scn = small()
    area = {}
    for name, kw in (("nominal", {}), ("long", {"exposure": 3.0}), ("thin", {"sun_transmittance": 0.3})):
        grey = cv2.cvtColor(render_sky(scn, T_MORNING, **kw).image, cv2.COLOR_BGR2GRAY)
        area[name] = int((grey >= 254).sum())
    assert area["long"] > 1.5 * area["nominal"] > 1.5 * area["thin"] > 0


def test_a_cloud_over_the_sun_hides_it_and_the_truth_says_so():
    scn = small()
    fr = render_sky(scn, T_MORNING, sun_transmittance=0.0)
    grey = cv2.cvtColor(fr.image, cv2.COLOR_BGR2GRAY)
    assert fr.truth["visibility"] == "hidden" and grey.max() < 250
    clouds = small(clouds=CloudField(coverage=1.0, tau_max=20.0))
    fr = render_sky(clouds, T_MORNING)
    assert fr.truth["transmittance"] < 1e-3 and fr.truth["visibility"] == "hidden"


def test_ccd_smear_lights_the_sun_column_and_bloom_saturates_it():
    base = small()
    u, v = render_sky(base, T_MORNING).truth["sun_uv"]
    col, row_far = round(u), round(v) + 60
    plain = cv2.cvtColor(render_sky(base, T_MORNING).image, cv2.COLOR_BGR2GRAY)
    ccd = cv2.cvtColor(
        render_sky(base.with_(glare=replace(base.glare, smear="ccd", smear_level=0.3)), T_MORNING).image,
        cv2.COLOR_BGR2GRAY,
    )
    assert int(ccd[row_far, col]) - int(plain[row_far, col]) > 40
    assert abs(int(ccd[row_far, col + 40]) - int(plain[row_far, col + 40])) < 3
    bloom = cv2.cvtColor(
        render_sky(base.with_(glare=replace(base.glare, smear="bloom", smear_level=2.0)), T_MORNING).image,
        cv2.COLOR_BGR2GRAY,
    )
    assert (bloom[:, col] >= 254).sum() > 1.5 * (plain[:, col] >= 254).sum()


def test_distractors_are_bright_where_the_truth_puts_them():
    scn = small(
        distractors=(
            SpecularReflection(az_deg=250.0, el_deg=30.0, strength=0.9),
            AircraftGlint(az0_deg=20.0, el0_deg=50.0, t0=T_MORNING - 10, radius_px=1.5),
            FlareGhost(position=0.7, radius_px=5.0, level=1.4),
        )
    )
    fr = render_sky(scn, T_MORNING)
    grey = cv2.cvtColor(fr.image, cv2.COLOR_BGR2GRAY)
    kinds = {d["kind"]: d for d in fr.truth["distractors"]}
    assert set(kinds) == {"reflection", "glint", "ghost"}
    for d in kinds.values():
        u, v = (round(x) for x in d["uv"])
        assert grey[v, u] >= 240, d["kind"]


def test_noise_is_reproducible_with_a_seeded_generator():
    scn = small(noise=True)
    a = render_sky(scn, T_MORNING, rng=np.random.default_rng(4)).image
    b = render_sky(scn, T_MORNING, rng=np.random.default_rng(4)).image
    c = render_sky(scn, T_MORNING, rng=np.random.default_rng(5)).image
    assert np.array_equal(a, b) and not np.array_equal(a, c)


def test_bad_requests_raise_hil_errors():
    with pytest.raises(HilError):
        sky_profile("nope")
    with pytest.raises(HilError):
        render_sky(small(), T_MORNING, sun_transmittance=1.5)


def test_checkerboard_corners_are_where_the_lens_puts_them():
    lens = seed_lens()
    rng = np.random.default_rng(2)
    ((rvec, tvec),) = checkerboard_poses(lens, 1, rng, max_theta_deg=50)
    img = render_checkerboard(lens, rvec, tvec, rng=rng, noise_dn=0.0)
    ok, c = cv2.findChessboardCorners(img, (9, 6))
    assert ok
    c = cv2.cornerSubPix(img, c, (3, 3), (-1, -1), (3, 50, 1e-4)).reshape(-1, 2)
    R = cv2.Rodrigues(rvec)[0]
    pts = board_corners() @ R.T + tvec
    uv, _ = lens.project(pts / np.linalg.norm(pts, axis=1, keepdims=True))
    # OpenCV may number the corners from either end
    err = min(np.abs(c - uv).max(), np.abs(c[::-1] - uv).max())
    assert err < 0.15


def test_glare_model_amplitude_saturates_at_its_radius():
    g = GlareModel(radius_deg=3.0)
    assert g.amplitude * float(g.profile(3.0)) == pytest.approx(1.0)
