"""The fisheye sensor's parts: the OpenCV lens wrapper, the cone fit, the seed pipeline."""

import math

import cv2
import numpy as np
import pytest

from controller.vision.fisheye import FisheyeEstimator, FisheyeLens, SeedEstimator
from controller.vision.fisheye.seed import K_H, K_I, K_S, segment, weighted_hsi
from controller.vision.fisheye.sphere import fit_cone, tangent_basis, tangent_frame
from hil.skycam import render_sky, seed_lens

from .helpers import small_scene, truth_bundle, utc


def test_lens_rays_match_the_worlds_lens_to_95_degrees():
    world = seed_lens()
    lens = FisheyeLens(world.K, world.D, world.width, world.height)
    rng = np.random.default_rng(0)
    th = rng.uniform(0, np.radians(95), 300)
    ph = rng.uniform(-np.pi, np.pi, 300)
    d = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], 1)
    uv, _ = world.project(d)
    back, ok = lens.rays(uv)
    assert ok.all()
    assert np.degrees(np.arccos(np.clip((back * d).sum(1), -1, 1))).max() < 1e-4
    front = d[:, 2] > 0
    uv2, ok2 = lens.project(d[front])
    assert ok2.all() and np.abs(uv2 - uv[front]).max() < 1e-6


def test_a_skewed_lens_projects_as_it_inverts():
    # cv2.fisheye.projectPoints takes the skew as its ``alpha``, not from K[0, 1]: a K with a
    # skew had put pixels 0.5 px off the rays they came from
    K = np.array([[166.2, 0.4, 319.7], [0, 165.8, 240.1], [0, 0, 1]])
    lens = FisheyeLens(K, [0.02, -0.01, 0.003, -0.0005], 640, 480)
    rng = np.random.default_rng(3)
    th, ph = rng.uniform(0, np.radians(88), 200), rng.uniform(-np.pi, np.pi, 200)
    d = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], 1)
    uv, ok = lens.project(d)
    back, ok2 = lens.rays(uv)
    assert ok.all() and ok2.all()
    assert np.degrees(np.arccos(np.clip((back * d).sum(1), -1, 1))).max() < 1e-4  # 0.14 before


def test_directions_project_as_opencv_projects_them():
    K = np.array([[166.2, 0.4, 319.7], [0, 165.8, 240.1], [0, 0, 1]])
    for D in ([0.02, -0.01, 0.003, -0.0005], [0.0, 0.0, 0.0, 0.0], [-0.05, 0.01, 0.0, 0.0]):
        lens = FisheyeLens(K, D, 640, 480)
        rng = np.random.default_rng(4)
        d = rng.normal(size=(2000, 3))
        d[:, 2] = np.abs(d[:, 2]) + 1e-6
        d[0] = (0.0, 0.0, 1.0)  # the axis itself: no radius to divide by
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        uv, ok = lens.project_cv(d)
        assert [lens.project_one(*p) for p in d.tolist()] == [tuple(q) for q in uv.tolist()]
        # OpenCV's formula in numpy: within rounding of OpenCV's own
        mine, ok2 = lens.project(d)
        assert ok.all() and ok2.all() and np.abs(mine - uv).max() < 1e-10
    assert lens.project_one(0.1, 0.2, 0.0) is None and lens.project_one(0.0, 0.6, -0.8) is None
    # behind the lens: not valid, put at the principal point, as OpenCV's call is given them
    back = np.array([[0.1, 0.2, 0.0], [0.0, 0.6, -0.8], [0.6, 0.0, 0.8]] * 3)
    for n in (1, 3, 9):
        uv, ok = lens.project(back[:n])
        ref, ok_ref = lens.project_cv(back[:n])
        assert ok.tolist() == ok_ref.tolist() and np.abs(uv - ref).max() < 1e-10


def test_a_directions_image_moves_as_the_projections_differences_say():
    """:meth:`project_one_moving`: the pixel of :meth:`project_one`, bit for bit, and its
    motion along two tangents, as central differences give it (on the axis too)."""
    K = np.array([[166.2, 0.4, 319.7], [0, 165.8, 240.1], [0, 0, 1]])
    lens = FisheyeLens(K, [0.02, -0.01, 0.003, -0.0005], 640, 480)
    rng = np.random.default_rng(6)
    d = rng.normal(size=(500, 3))
    d[:, 2] = np.abs(d[:, 2]) + 0.05
    d[0] = (0.0, 0.0, 1.0)
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    h = 1e-6
    for p in d.tolist():
        e1, e2 = tangent_frame(*p)
        uv, moves = lens.project_one_moving(tuple(p), e1, e2)
        assert uv == lens.project_one(*p)
        for e, m in zip((e1, e2), moves):
            ends = [
                lens.project_one(*(q / np.linalg.norm(q)))
                for q in (np.add(p, np.multiply(h, e)), np.subtract(p, np.multiply(h, e)))
            ]
            diff = (np.array(ends[0]) - np.array(ends[1])) / (2 * h)
            assert np.abs(diff - m).max() < 1e-5 * max(1.0, np.abs(diff).max())
    assert lens.project_one_moving((0.6, 0.0, -0.8), (0.0, 1.0, 0.0), (0.8, 0.0, 0.6)) is None


def test_tangent_frame_in_floats_is_tangent_basis():
    rng = np.random.default_rng(6)
    for a in rng.normal(size=(500, 3)):
        a /= np.linalg.norm(a)
        e1, e2 = tangent_basis(a)
        f1, f2 = tangent_frame(*a.tolist())
        assert e1.tolist() == list(f1) and e2.tolist() == list(f2)
        assert abs(e1 @ a) < 1e-12 and abs(e1 @ e2) < 1e-12 and np.allclose(np.cross(e1, e2), a)


def test_lens_rays_of_a_stereographic_lens_hold_past_where_opencv_clamps_them():
    # r = 2 f tan(theta / 2) as a cv2.fisheye fit: its distorted radius passes pi / 2 at
    # 76 deg, where cv2.fisheye.undistortPoints clamps it (rays 6 deg off at 85 deg)
    f, th = 112.0, np.linspace(0.0, np.radians(95.0), 2000)
    A = np.stack([th, th**3, th**5, th**7, th**9], 1)
    c, *_ = np.linalg.lstsq(A, 2 * np.tan(th / 2), rcond=None)
    K = np.array([[f * c[0], 0, 320.0], [0, f * c[0], 240.0], [0, 0, 1]])
    D = c[1:] / c[0]
    lens = FisheyeLens(K, D, 640, 480)
    rng = np.random.default_rng(1)
    t = rng.uniform(0, np.radians(94.9), 400)
    ph = rng.uniform(-np.pi, np.pi, 400)
    d = np.stack([np.sin(t) * np.cos(ph), np.sin(t) * np.sin(ph), np.cos(t)], 1)
    td = t * (1 + D[0] * t**2 + D[1] * t**4 + D[2] * t**6 + D[3] * t**8)
    uv = np.stack([320.0 + K[0, 0] * td * np.cos(ph), 240.0 + K[1, 1] * td * np.sin(ph)], 1)
    back, ok = lens.rays(uv)
    assert ok.all()
    assert np.degrees(np.arccos(np.clip((back * d).sum(1), -1, 1))).max() < 1e-4
    # beyond the limit, or beyond where the polynomial stops rising, no ray
    far = np.radians(97.0)
    r_far = far * (1 + D[0] * far**2 + D[1] * far**4 + D[2] * far**6 + D[3] * far**8)
    assert not lens.rays([[320.0 + K[0, 0] * r_far, 240.0]])[1][0]
    # the local scale there is the lens's, not the clamp's (0.26 deg per px at 85 deg)
    t85 = np.radians(85.0)
    u85 = 320.0 + K[0, 0] * t85 * (1 + D[0] * t85**2 + D[1] * t85**4 + D[2] * t85**6 + D[3] * t85**8)
    dr = f * 1.0 / np.cos(t85 / 2) ** 2  # px per rad, radial
    dt = f * 2 * np.tan(t85 / 2) / np.sin(t85)  # px per rad, tangential
    assert lens.deg_per_px(u85, 240.0) == pytest.approx(np.degrees(1 / np.sqrt(dr * dt)), rel=0.01)


def _circle(axis, rho, n, rng, noise=0.0):
    e1, e2 = tangent_basis(axis)
    ph = np.linspace(0, 2 * np.pi, n, endpoint=False)
    r = rho + rng.normal(0, noise, n)
    return np.cos(r)[:, None] * axis + np.sin(r)[:, None] * (
        np.cos(ph)[:, None] * e1 + np.sin(ph)[:, None] * e2
    )


def test_cone_fit_ignores_a_bulge_and_a_dent():
    rng = np.random.default_rng(1)
    a = np.array([0.3, -0.2, 0.9])
    a /= np.linalg.norm(a)
    v = _circle(a, math.radians(4.0), 120, rng, noise=math.radians(0.01))
    bulge = _circle(a, math.radians(6.0), 120, rng)[:25]  # a saturated cloud edge
    dent = _circle(a, math.radians(2.5), 120, rng)[60:75]  # a cloud over part of the rim
    pts = np.concatenate([v[25:60], v[75:], bulge, dent])
    axis, rho, inl, _rms, _ = fit_cone(pts)
    assert math.degrees(math.acos(min(1.0, axis @ a))) < 0.01
    assert math.degrees(rho) == pytest.approx(4.0, abs=0.01)
    assert not inl[-40:].any()


def test_cone_fit_accepts_an_ellipse_without_calling_it_outliers():
    np.array([0.0, 0.0, 1.0])
    ph = np.linspace(0, 2 * np.pi, 90, endpoint=False)
    r = np.radians(4.0) * (1 + 0.3 * np.cos(2 * ph))
    v = np.stack([np.sin(r) * np.cos(ph), np.sin(r) * np.sin(ph), np.cos(r)], 1)
    axis, _rho, inl, _rms, ell = fit_cone(v)
    assert inl.all() and math.degrees(math.acos(axis[2])) < 1e-6
    assert np.hypot(*ell) == pytest.approx(np.radians(1.2), rel=0.05)


def test_a_frames_result_does_not_depend_on_the_frame_before_it():
    # the estimator works in frame-sized buffers kept between frames (FrameBuffers)
    scn = small_scene()
    a, b = (render_sky(scn, utc(2025, 6, 21, h)).image for h in (8, 12))
    fresh = FisheyeEstimator(truth_bundle(scn)).estimate_image(b)
    est = FisheyeEstimator(truth_bundle(scn))
    est.estimate_image(a)
    est.estimate_image(np.zeros_like(a))
    again = est.estimate_image(b)
    assert fresh.found and again.found
    assert (again.az_deg, again.el_deg, again.sigma_deg) == (fresh.az_deg, fresh.el_deg, fresh.sigma_deg)


def test_hsi_formulas_and_the_papers_weights():
    px = np.array([[[0, 0, 255], [0, 255, 0], [255, 0, 0], [128, 128, 128], [255, 255, 255]]], np.uint8)
    h, s, i = weighted_hsi(px)  # BGR: red, green, blue, grey, white
    np.testing.assert_allclose(h[0] / K_H, [0.0, 1 / 3, 2 / 3, 0.0, 0.0], atol=1e-6)
    np.testing.assert_allclose(s[0] / K_S, [1, 1, 1, 0, 0], atol=1e-6)
    np.testing.assert_allclose(i[0] / K_I, [1 / 3, 1 / 3, 1 / 3, 128 / 255, 1.0], atol=1e-6)
    assert segment(px, 0.10)[0].tolist() == [0, 0, 0, 0, 255]


def test_longitude_correction_stretches_each_row_to_the_full_circle():
    scn = small_scene()
    est = SeedEstimator(truth_bundle(scn))
    R, x0, y0 = est.radius, est.x0, est.y0
    m = np.zeros((scn.lens.height, scn.lens.width), np.uint8)
    row = round(y0 + 0.6 * R)
    half = math.sqrt(R * R - (row - y0) ** 2)
    m[row, round(x0 + 0.5 * half)] = 255  # half way to the circle's edge on that row
    ys, xs = np.nonzero(est.correct(m))
    assert set(ys) == {row}
    assert xs.mean() == pytest.approx(x0 + 0.5 * R, abs=1.5)


def test_seed_rules_shape_area_and_offset():
    scn = small_scene()
    b = truth_bundle(scn)
    est = SeedEstimator(b, n_t=100.0)
    H, W = scn.lens.height, scn.lens.width

    def frame(draw):
        img = np.zeros((H, W, 3), np.uint8)
        draw(img)
        return img

    round_spot = frame(lambda im: cv2.circle(im, (160, 120), 6, (255, 255, 255), -1))
    bar = frame(lambda im: cv2.rectangle(im, (150, 115), (175, 119), (255, 255, 255), -1))
    huge = frame(lambda im: cv2.circle(im, (160, 120), 15, (255, 255, 255), -1))
    assert est.estimate_image(round_spot, 0.0).found
    est.reset_sequence()
    assert est.estimate_image(bar, 0.0).extra["rejected"]["shape"] == 1
    assert est.estimate_image(huge, 0.0).extra["rejected"]["area"] == 1
    est.reset_sequence()
    est.estimate_image(round_spot, 0.0)
    far = frame(lambda im: cv2.circle(im, (230, 120), 6, (255, 255, 255), -1))
    assert est.estimate_image(far, 1.0).extra["rejected"]["offset"] == 1


def test_seed_offsets_and_direction_on_a_rendered_frame():
    scn = small_scene()
    t = utc(2025, 6, 21, 8, 0)  # the sun 14 deg from the axis
    fr = render_sky(scn, t)
    res = SeedEstimator(truth_bundle(scn), n_t=100.0).estimate_image(fr.image, t)
    assert res.found, res.extra
    W, H = scn.lens.width, scn.lens.height
    U, V = res.extra["corrected_uv"]
    assert res.offset_px == pytest.approx((U - W / 2, V - H / 2), abs=1e-3)
    err = math.degrees(math.acos(float(np.clip(res.d_cam @ fr.truth["sun_cam"], -1, 1))))
    # the paper's hemisphere is orthographic (r = R sin theta); this lens is near equidistant,
    # which puts the sun ~4 deg too close to the axis here: the paper's model, reproduced
    assert 2.0 < err < 6.0


def test_only_a_raise_on_the_horizons_side_lowers_the_rim():
    """The clear sky next to a low sun brightens towards the horizon, where the rim clips;
    a raise pointing elsewhere is a cloud's, and the rim's level stays."""
    from controller.vision.fisheye.rimsky import horizon_side_excess

    a = np.array([0.0, math.sin(math.radians(60)), math.cos(math.radians(60))])  # 30 deg up
    up = np.array([0.0, 0.0, 1.0])
    e1, e2 = tangent_basis(a)
    phi = np.linspace(0, 2 * math.pi, 72, endpoint=False)
    down = float(up @ a) * a - up
    toward = np.cos(phi) * float(e1 @ down) + np.sin(phi) * float(e2 @ down)  # along down
    horizon_side = 20.0 * toward / np.abs(toward).max()
    assert horizon_side_excess(horizon_side, phi, a, e1, e2, up) == pytest.approx(20.0, rel=1e-3)
    assert horizon_side_excess(-horizon_side, phi, a, e1, e2, up) == 0.0  # brighter towards the zenith
    sideways = 20.0 * (
        np.cos(phi) * float(e1 @ np.cross(a, down)) + np.sin(phi) * float(e2 @ np.cross(a, down))
    )
    assert horizon_side_excess(sideways, phi, a, e1, e2, up) == 0.0
    assert horizon_side_excess(horizon_side, phi, a, e1, e2, None) == 0.0  # horizon unknown


def test_the_fit_ends_on_an_axis_the_sky_was_read_around(monkeypatch):
    """The sky model's term for the axis's error is a linearisation about the axis it is
    read around: once the axis has settled, the sky's rings are read again around it, and
    the fit does not end on an axis the sky was not read around (at most three readings)."""
    import controller.vision.fisheye.glare as glare

    events: list[str] = []
    tangent, read = glare.tangent_basis, glare.read_sky

    def counting_tangent(a):
        events.append("pass")
        return tangent(a)

    def counting_read(*args, **kw):
        events.append("sky")
        return read(*args, **kw)

    monkeypatch.setattr(glare, "tangent_basis", counting_tangent)
    monkeypatch.setattr(glare, "read_sky", counting_read)
    scn = small_scene(scale=1.0)
    t = utc(2025, 3, 20, 4, 0)  # a low sun: the axis settles after the first two readings
    res = FisheyeEstimator(truth_bundle(scn)).estimate_image(render_sky(scn, t).image, t)
    assert res.found
    assert events[-2:] == ["pass", "sky"]
    assert events.count("sky") == 3
