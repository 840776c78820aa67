import cv2
import numpy as np
import pytest

from controller.calibration.azimuth import ephemeris_offset, ephemeris_rotation, fit_lobe_coeff, noon_offset
from controller.calibration.bundle import CameraCal
from controller.calibration.level import zenith_from_lines
from controller.calibration.pose import solve_pose
from controller.calibration.surface import (
    estimate_normals,
    fit_radial_poly,
    fit_sphere_points,
    radial_poly_eval,
    read_cloud,
)
from controller.errors import InputError
from controller.sun.types import angle_between_deg
from controller.vision.mirror import lobe_correct

CAM = CameraCal(800, 600, 700.0, 702.0, 401.0, 298.0, (-0.12, 0.05, 1e-4, -2e-4, 0.0))


def _sphere_points(n, rng, c=(0.01, -0.02, 0.003), r=0.2, noise=0.0):
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    u[:, 2] = np.abs(u[:, 2])
    return np.asarray(c) + r * u + rng.normal(0, noise, (n, 3)), u


def test_sphere_fit_recovers_centre_radius_and_reports_rmse():
    rng = np.random.default_rng(0)
    pts, _ = _sphere_points(5000, rng, noise=0.0002)
    c, r, rmse = fit_sphere_points(pts)
    np.testing.assert_allclose(c, [0.01, -0.02, 0.003], atol=2e-5)
    assert abs(r - 0.2) < 2e-5
    assert 0.00017 < rmse < 0.00023  # radial part of 0.2 mm isotropic noise


def test_normals_by_local_plane_fit(tmp_path):
    rng = np.random.default_rng(1)
    pts, u = _sphere_points(20000, rng)
    p = tmp_path / "c.xyz"
    np.savetxt(p, pts)
    pts2, nrm = read_cloud(p)
    assert nrm is None
    n = estimate_normals(pts2, outward_from=[0.01, -0.02, 0.003])
    ang = angle_between_deg(n, u)
    assert np.median(ang) < 1.0 and np.percentile(ang, 95) < 3.0


def test_unreadable_cloud_is_an_input_error(tmp_path):
    p = tmp_path / "bad.ply"
    p.write_text("ply\nformat ascii 1.0\nelement vertex 100\nproperty float x\nend_header\n1\n")
    with pytest.raises(InputError):
        read_cloud(p)


def test_radial_poly_captures_low_order_bumps():
    from hil.camera import Globe

    g = Globe(bump_amplitude_m=0.001)
    rng = np.random.default_rng(2)
    pts, _ = g.surface_points(30000, rng)
    coef, rmse = fit_radial_poly(pts, [0, 0, 0], 0.2, 6)
    u = rng.normal(size=(2000, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    u[:, 2] = np.abs(u[:, 2])
    h_true, _ = g.height(u)
    h_fit, _ = radial_poly_eval(u, coef, 6)
    assert np.sqrt(np.mean((h_fit - h_true) ** 2)) < 3e-5  # < 0.03 mm
    assert np.std(h_true) > 1e-4  # the bumps are real (test can fail)


def test_pnp_recovers_the_pose():
    rng = np.random.default_rng(3)
    model = np.c_[rng.uniform(-0.3, 0.3, (20, 2)), np.zeros(20)]
    rvec = np.array([2.3, -0.4, 0.2])
    tvec = np.array([0.01, 0.04, 0.8])
    uv, _ = cv2.projectPoints(model, rvec, tvec, CAM.K, CAM.dist_array)
    uv = uv.reshape(-1, 2) + rng.normal(0, 0.1, (20, 2))
    res = solve_pose(model, uv, CAM)
    R0, R1 = cv2.Rodrigues(rvec)[0], cv2.Rodrigues(res.rvec)[0]
    assert np.degrees(np.linalg.norm(cv2.Rodrigues(R1 @ R0.T)[0])) < 0.05
    assert res.rms_px < 0.2


def test_zenith_from_plumb_lines_and_outlier_rejection():
    rng = np.random.default_rng(4)
    rvec = np.array([2.2, -0.3, 0.1])
    tvec = np.array([0.0, 0.05, 0.7])
    R = cv2.Rodrigues(rvec)[0]
    C = -R.T @ tvec
    zen = np.array([0.01, -0.02, 1.0])
    zen /= np.linalg.norm(zen)
    lines = []
    for _ in range(5):
        ray = R.T @ np.array([rng.uniform(-0.4, 0.4), rng.uniform(-0.2, 0.2), 1.0])
        P = C + 0.5 * ray / np.linalg.norm(ray)
        seg = P + np.linspace(-0.15, 0.15, 30)[:, None] * zen
        uv, _ = cv2.projectPoints(seg, rvec, tvec, CAM.K, CAM.dist_array)
        lines.append(uv.reshape(-1, 2))
    res = zenith_from_lines(lines, CAM, rvec)
    assert angle_between_deg(res.zenith_model, zen) < 1e-3
    bad = lines + [lines[0] + np.c_[np.linspace(0, 15, 30), np.zeros(30)]]  # a leaning "string"
    res2 = zenith_from_lines(bad, CAM, rvec)
    assert res2.n_lines == 5 and angle_between_deg(res2.zenith_model, zen) < 1e-3


def test_azimuth_alignment_noon_and_ephemeris():
    from controller.sun.source import Site, solar_position

    site = Site(32.4835, 48.3364)
    ts = 1742460600.0 + np.arange(-4 * 3600, 4 * 3600 + 1, 900)  # around noon (08:50Z), 2025-03-20
    sp = solar_position(site, ts)
    az_true = sp["azimuth"].to_numpy()
    el = sp["apparent_elevation"].to_numpy()
    offset = 243.926
    az_lev = (az_true + offset) % 360
    assert abs((noon_offset(az_lev, el) - offset + 180) % 360 - 180) < 0.2
    assert abs((ephemeris_offset(az_lev, el, az_true) - offset + 180) % 360 - 180) < 1e-9


def test_full_rotation_and_lobe_fit_recover_truth():
    from controller.sun.types import azel_to_enu, enu_to_azel
    from controller.vision import level_rotation

    rng = np.random.default_rng(5)
    s_enu = azel_to_enu(rng.uniform(60, 300, 40), rng.uniform(5, 80, 40))
    Rme = cv2.Rodrigues(np.array([0.004, -0.003, 0.4]))[0]  # model -> enu
    s_model = s_enu @ Rme
    zen, off = ephemeris_rotation(s_model, s_enu)
    assert angle_between_deg(zen, Rme.T @ [0, 0, 1]) < 1e-9
    az_l, _ = enu_to_azel(level_rotation(zen) @ s_model[0])
    az_t, _ = enu_to_azel(s_enu[0])
    assert abs(((az_l - off) - az_t + 180) % 360 - 180) < 1e-6
    vbar = np.tile([0.0, -0.6, 0.8], (40, 1))
    biased = np.array([lobe_correct(s, vb, -0.17) for s, vb in zip(s_model, vbar)])  # add bias
    assert abs(fit_lobe_coeff(biased, vbar, s_model) - 0.17) < 0.01


def test_intrinsics_from_rendered_checkerboards():
    from controller.calibration.intrinsics import calibrate_intrinsics
    from hil.camera import CameraModel, checkerboard_poses, render_checkerboard

    cam = CameraModel(480, 360, 400.0, 400.0, 241.0, 178.5, (-0.15, 0.05, 0, 0, 0))
    rng = np.random.default_rng(6)
    imgs = [render_checkerboard(cam, rv, tv, rng=rng) for rv, tv in checkerboard_poses(cam, 10, rng)]
    res = calibrate_intrinsics(imgs, (9, 6), 0.04)
    assert res.rms_px < 0.2
    assert abs(res.camera.fx - 400) < 2 and abs(res.camera.cx - 241) < 2
    assert abs(res.camera.dist[0] + 0.15) < 0.02
    with pytest.raises(InputError):
        calibrate_intrinsics(imgs[:2], (9, 6), 0.04)
