"""The default pipeline on frames of the second renderer (benchmarks.fisheye_other): another
lens model, sky model, glare profile and tone curve than the HIL world's."""

from dataclasses import replace

import numpy as np
import pytest

from benchmarks import fisheye_other as other
from controller.sun.types import angle_between_deg, azel_to_enu
from controller.vision.fisheye import FisheyeEstimator
from controller.vision.fisheye.default import FisheyeOptions
from controller.vision.fisheye.locator import UNKNOWN_MAX_MOVE_DEG


def _run(look, days=((2025, 3, 20), (2025, 6, 21)), el_range=(5.0, 90.0), declared=False):
    """(elevation, error, sigma) of each frame found; ``declared``: the bundle carries the
    camera's radiometry (:func:`benchmarks.fisheye_other.radiometry`)."""
    rays, R = other.pixel_rays(), other.rotation()
    ts = np.concatenate([other.utc_midnight(*d) + np.arange(0, 86400, 1800, dtype=float) for d in days])
    _, els = other.sun_truth(ts)
    est = FisheyeEstimator(other.bundle(R, look if declared else None))
    rows = []
    for t, el in zip(ts, els):
        if not el_range[0] <= el <= el_range[1]:
            continue
        img, truth = other.render(look, float(t), rays, R, np.random.default_rng(1))
        res = est.estimate_image(img, float(t))
        if res.found:
            err = angle_between_deg(azel_to_enu(res.az_deg, res.el_deg), truth["sun_enu"])
            rows.append((el, err, res.sigma_deg))
    return np.array(rows)


def test_the_renderers_lens_is_handed_over_as_a_close_kannala_brandt_fit():
    K, D = other.kb_fit()
    th = np.radians(np.linspace(0.5, 94.0, 200))
    td = th * (1 + D[0] * th**2 + D[1] * th**4 + D[2] * th**6 + D[3] * th**8)
    assert np.abs(td - 2 * np.sin(th / 2)).max() * other.SENSOR.f_eq < 0.05  # px


def test_a_finer_sensor_sees_the_same_directions_at_twice_the_pixels():
    fine = other.SENSOR.scaled(2.0)
    assert (fine.width, fine.height) == (1280, 960)
    d = np.array([0.3, -0.2, 0.0])
    d[2] = np.sqrt(1 - d @ d)
    u1, v1 = other.project(d)
    u2, v2 = other.project(d, fine)
    assert (u2, v2) == pytest.approx(((u1 + 0.5) * 2 - 0.5, (v1 + 0.5) * 2 - 0.5))
    rays, inside = other.pixel_rays(fine)
    assert rays.shape == (960, 1280, 3) and inside[480, 640]
    iu, iv = int(round(u2)), int(round(v2))
    assert float(rays[iv, iu] @ d) > np.cos(np.radians(0.5))
    with pytest.raises(ValueError, match="1280 x 960 sensor"):
        other.render(other.OtherLook("x"), 0.0, other.pixel_rays(), other.rotation(), None, fine)


def test_high_sun_is_within_the_clear_sky_target():
    rows = _run(other.OtherLook("clear"), el_range=(35.0, 90.0))
    assert len(rows) >= 8
    assert np.sqrt(np.mean(rows[:, 1] ** 2)) < 0.04


def test_sigma_is_honest_at_low_sun_under_a_cie_sky():
    """A low sun under the CIE clear sky is off by tenths of a degree (the sky's structure
    around it is modelled only in part); before the sky's share entered sigma, 64 % of the
    frames were within 2 sigma, one at 5.6 sigma."""
    rows = _run(other.OtherLook("clear"), el_range=(12.0, 35.0))
    assert len(rows) >= 8
    assert np.mean(rows[:, 1] < 2 * rows[:, 2]) >= 0.9


def test_a_low_sun_under_a_cie_sky_keeps_its_whole_rim():
    """Next to a low sun the CIE sky plus the glare clips on the horizon's side before the
    glare alone reaches the rim's level; with the rim's level held at 0.85 of the contrast
    those rays were dropped and the half rim left read the sun 0.31 deg RMS off (10 frames,
    15-30 deg); with the level lowered until those on the horizon's side stay under the
    clip, 0.13 (11).  With the sky read again once the axis settled, the two at 17-18 deg
    (0.12 and 0.15 off, sigma 0.65 and 0.53) are refused (``incomplete_glare``): 0.10 (8)."""
    rows = _run(other.OtherLook("clear"), el_range=(15.0, 30.0))
    assert len(rows) >= 8
    assert np.sqrt(np.mean(rows[:, 1] ** 2)) < 0.12


def test_noise_added_after_the_clip_does_not_hide_the_rim():
    """A renderer (or camera pipeline) that adds its noise to the output leaves the glare's
    saturated plateau noisy: pixels under the saturation threshold riddle the blob, whose
    inscribed disk (the rays' first radius) shrank well inside the glare, so the rays ended
    before the rim (``no_rim``: 9 of the 39 frames above 20 deg were not found)."""
    look = other.OtherLook("noise after the clip", tone="linear", post_noise=3.0)
    rows = _run(look, el_range=(20.0, 90.0))
    ts = np.concatenate(
        [
            other.utc_midnight(*d) + np.arange(0, 86400, 1800, dtype=float)
            for d in ((2025, 3, 20), (2025, 6, 21))
        ]
    )
    n = int((other.sun_truth(ts)[1] >= 20.0).sum())
    assert len(rows) >= n - 1, f"{len(rows)} of {n} found"
    assert np.sqrt(np.mean(rows[:, 1] ** 2)) < 0.05


def test_a_declared_srgb_response_and_vignetting_carry_the_sky_to_the_rim():
    """The sky next to a sun 17-40 deg high is measured a few radii out, in grey far under
    the rim's; on an sRGB camera whose lens darkens towards the edge that gradient, taken to
    the rim as grey, moved the rim by nearly twice what the sky adds there (0.07-0.11 deg
    high, all frames).  With the response and the vignetting declared the sky is modelled in
    light and each ray's rim level turned back into grey."""
    look = other.OtherLook("clear")
    before = _run(look, el_range=(17.0, 40.0))
    after = _run(look, el_range=(17.0, 40.0), declared=True)
    rms = [float(np.sqrt(np.mean(r[:, 1] ** 2))) for r in (before, after)]
    print(
        f"17-40 deg: {len(before)} frames, rms {rms[0]:.4f} undeclared; {len(after)} frames, rms {rms[1]:.4f} declared"
    )
    assert len(after) >= len(before) - 1
    assert rms[1] < 0.03


def test_the_radiometry_calibrated_from_the_renderers_own_frames_serves_as_well():
    """The same, with the response and the vignetting measured as an installer would
    (``calibrate fisheye response`` on 8 brackets of the sunless sky, ``vignetting`` on 3
    flat fields of a dome), not stated."""
    cal = other.calibrated_radiometry("srgb", 0.25)
    x = np.linspace(0.0, 1.0, 4097)
    srgb = np.interp(np.arange(256) / 255.0, other.tone_curve(x, "srgb"), x)
    assert np.abs(np.asarray(cal.table) - srgb)[20:236].max() < 0.006
    look = other.OtherLook("clear", radiometry="calibrated")
    rows = _run(look, el_range=(17.0, 40.0), declared=True)
    rms = float(np.sqrt(np.mean(rows[:, 1] ** 2)))
    print(f"17-40 deg, calibrated: {len(rows)} frames, rms {rms:.4f}")
    assert len(rows) >= 16
    assert rms < 0.03


def _bench_days(look):
    """(elevation, error) of each frame found on the bench's three clear days (the bench's
    frames: one generator, seed 17, through the days in order), radiometry declared."""
    rays, R = other.pixel_rays(), other.rotation()
    est = FisheyeEstimator(other.bundle(R, look))
    rng = np.random.default_rng(17)
    rows, n = [], 0
    for day in ((2025, 3, 20), (2025, 6, 21), (2025, 12, 21)):
        est.reset_sequence()
        ts = other.utc_midnight(*day) + np.arange(0, 86400, 1800, dtype=float)
        _, els = other.sun_truth(ts)
        for t in ts[els >= 5.0]:
            img, truth = other.render(look, float(t), rays, R, rng)
            n += 1
            res = est.estimate_image(img, float(t))
            if res.found:
                err = angle_between_deg(azel_to_enu(res.az_deg, res.el_deg), truth["sun_enu"])
                rows.append((truth["el_deg"], err))
    return np.array(rows), n


def _bench_rms(look, label: str) -> tuple[np.ndarray, float]:
    """:func:`_bench_days`'s frames found and their RMS error (deg), printed."""
    rows, n = _bench_days(look)
    rms = float(np.sqrt(np.mean(rows[:, 1] ** 2)))
    print(f"{label}: {len(rows)} of {n} found, rms {rms:.4f}, max {rows[:, 1].max():.3f}")
    return rows, rms


def test_a_rim_whose_gap_is_the_skys_next_to_a_low_sun_is_not_trusted():
    """A wide glare (5 deg) next to a sun 15-19 deg high: the clear sky brightens towards
    the horizon until the rays there find no rim, and the arc left (a 100-113 deg gap
    facing the horizon) carried the sky model's error into the centre: six frames 0.14-0.70
    deg off, 0.129 deg RMS over the days (55 of 68 found)."""
    rows, rms = _bench_rms(other.OtherLook("wide glare", sat_radius_deg=5.0), "wide glare")
    assert len(rows) >= 45
    assert rms < 0.04
    assert rows[:, 1].max() < 0.15


def test_a_bloom_that_spills_upwards_only_costs_only_the_rays_towards_it():
    """A sensor read one way spills its bloom upwards only, a dome two radii high over the
    glare.  Taken for no streak, its flanks pushed the upper rim out and the sun read
    0.17 deg off at every elevation (49 of 68 found); the rays within 40 deg of the streak
    are now left out, and the sky's dipole is fitted on the rest of the circle."""
    rows, rms = _bench_rms(other.OtherLook("other renderer, upward bloom 2 radii", bloom=2.0), "upward bloom")
    assert len(rows) >= 45
    assert rms < 0.03


def test_a_bloom_along_the_images_rows_costs_the_rays_towards_it_as_one_along_its_columns():
    """The same sensor's frames turned 90 deg (read out across the stored image), its bloom
    four radii long: taken for no streak, 42 of 68 frames were found at 0.110 deg RMS; found
    along the rows, 50 at 0.033, as the unturned frames read (0.032)."""
    look = other.OtherLook(
        "other renderer, upward bloom 4 radii, frame turned 90 deg", bloom=4.0, turned=True
    )
    rows, rms = _bench_rms(look, "upward bloom 4 radii, turned")
    assert len(rows) >= 48
    assert rms < 0.04


def test_a_glare_the_lens_squeezes_is_no_streak_along_the_rows():
    """No bloom, linear output (the calibration bench's frames, 20 min apart): a low sun
    near the top of the frame, its core squeezed along the image's radius and a little
    longer on the horizon's side, passed for the rows' short one-way streak and read 0.102
    deg off (0.057 without it). Along the rows only a streak that leaves the core unbroken
    counts."""
    from benchmarks.fisheye_selfcal import _second

    _, frames_of, bundle, _, days = _second(7, 1.0)
    est = FisheyeEstimator(bundle)
    for t, img, s in frames_of(days[0]):
        res = est.estimate_image(img, t)
        if int(t) == 1742490000:
            assert res.found and "bloom" not in res.quality
            assert angle_between_deg(azel_to_enu(res.az_deg, res.el_deg), s) < 0.07
            return
    raise AssertionError("no frame at 1742490000")


def test_a_hard_disk_and_halo_in_a_bright_sky_as_a_simple_renderer_draws_it():
    """A hard-edged saturated disk and an exponential halo, linear output, no vignetting (the
    bundle needs no radiometry).  With the sky measured on the first two passes only, a
    halo 0.6 deg off the sun at the second left the sky's model 70 % too strong for the rest
    of the fit: 0.111 deg RMS (52 of 68 found, one frame 0.66 off).  Read again once the
    axis has settled, and refused where the sky's correction moves the centre over 1 deg
    (three frames at 18-19 deg, 0.13-0.20 off) or sigma exceeds 1 deg: 0.026.  The camera's
    first two frames, before it has weighed its rim against its rings, lie between them, the
    rim moved 0.1 deg at most (``locator.UNKNOWN_MAX_MOVE_DEG``)."""
    rows, rms = _bench_rms(other.SIMPLE, "simple look")
    assert len(rows) >= 45
    assert rms < 0.03
    assert rows[2:, 1].max() < 0.08
    assert rows[:2, 1].max() < 0.08 + UNKNOWN_MAX_MOVE_DEG


def test_a_sky_read_around_a_rim_since_outgrown_is_read_again_not_kept():
    """Linear output, a 17-deg sun (20 Mar, 17:00 UTC): the first passes fit a 2-deg core,
    so the sky's rings lay inside the glare and read no dipole; the fit then settled on the
    3.8-deg rim with that sky, and the next reading, which moved the axis 0.7 deg, was taken
    for a cloud's and undone.  The sun read 0.73 deg low (sigma 0.22); in the selfcal bench's
    sequence it was the linear look's worst frame."""
    look = other.CLEAR_LOOKS[7]
    assert look.tone == "linear"
    rays, R = other.pixel_rays(), other.rotation()
    t = 1742490000.0
    img, truth = other.render(look, t, rays, R, np.random.default_rng(12))
    errs = []
    for drop in (True, False):  # the default; and a kept sky however stale (before)
        opts = FisheyeOptions()
        opts = replace(opts, glare=replace(opts.glare, drop_stale_sky=drop))
        res = FisheyeEstimator(other.bundle(R, look), opts).estimate_image(img, t)
        assert res.found
        errs.append(angle_between_deg(azel_to_enu(res.az_deg, res.el_deg), truth["sun_enu"]))
    assert errs[0] < 0.2
    assert errs[1] > 0.5  # the case is still in the frame


def _cie10_low_sun(t, seed, **opts):
    """CIE sky type 10 at type 12's circumsolar level: the result and error at time ``t``."""
    look = next(lk for lk in other.CLEAR_LOOKS if "CIE sky type 10" in lk.name)
    rays, R = other.pixel_rays(), other.rotation()
    img, truth = other.render(look, t, rays, R, np.random.default_rng(seed))
    res = FisheyeEstimator(other.bundle(R, look), replace(FisheyeOptions(), **opts)).estimate_image(img, t)
    err = angle_between_deg(azel_to_enu(res.az_deg, res.el_deg), truth["sun_enu"]) if res.found else None
    return res, err


def test_near_the_horizon_a_rim_whose_top_the_sky_model_drops_is_not_trusted():
    """A 5.3-deg sun (21 Dec) under CIE sky type 10: the sky is modelled by elevation, and
    its guesses at the rim's top and bottom are dropped, so the rim is two side arcs. Its
    largest gap (107 deg) faced the zenith, not the horizon, was taken for a cloud's (150
    deg allowed), and the sun read 0.29 deg high (sigma 0.84)."""
    res, _ = _cie10_low_sun(1766334600.0, 0, max_sigma_near_horizon_deg=1.0)
    assert not res.found and res.reason == "incomplete_glare"


def test_near_the_horizon_a_sun_placed_no_better_than_half_a_degree_is_refused():
    """A 7.1-deg sun (20 Mar) under CIE sky type 10, its rim's gaps just under 100 deg:
    read 0.29 deg high with sigma 0.76. Near the horizon the error is the elevation model's,
    the same frame after frame, so the bound on sigma is 0.5 deg there; an 11-deg sun of the
    same morning (sigma 0.3-0.4) is found."""
    res, err = _cie10_low_sun(1742454000.0, 1, max_sigma_near_horizon_deg=1.0)
    assert res.found and "near_horizon" in res.quality and res.sigma_deg > 0.5 and err > 0.2
    res, _ = _cie10_low_sun(1742454000.0, 1)
    assert not res.found and res.reason == "imprecise_glare"
    res, err = _cie10_low_sun(1742491800.0, 1)
    assert res.found and "near_horizon" in res.quality and err < res.sigma_deg < 0.5


def test_the_simple_look_draws_a_hard_saturated_disk_and_a_halo_under_full_scale():
    rays, R = other.pixel_rays(), other.rotation()
    t = other.utc_midnight(2025, 6, 21) + 12 * 3600.0  # a high sun
    look = replace(other.SIMPLE, noise=False)  # (and so no JPEG)
    img, truth = other.render(look, t, rays, R, np.random.default_rng(3))
    chi = np.degrees(np.arccos(np.clip((rays[0] @ R.T) @ truth["sun_enu"], -1, 1)))
    grey = img.min(axis=2)
    assert (grey[chi < 2.7] == 255).all()
    ring = grey[(chi > 3.4) & (chi < 3.8)]
    assert ring.size > 10 and ring.max() < 250
    assert other.bundle(R, other.SIMPLE).radiometry is None  # linear, evenly lit: nothing to declare


def test_a_rim_cut_on_the_horizons_side_carries_the_skys_correction_into_its_sigma_in_full():
    """The wide glare (5 deg) at 1280 x 960 next to a sun 18.5 deg high: the rays towards the
    horizon find no rim, and the arc left is moved by the sky's correction as a circle fitted
    to it is (:func:`.sphere.centre_move`), three times what the first harmonic of the moves
    over its rays says; the uncertainty takes that move."""
    from controller.vision.fisheye.channel import glare_channel
    from controller.vision.fisheye.glare import fit_glare

    sensor = other.SENSOR.scaled(2.0)
    look = other.OtherLook("wide glare", sat_radius_deg=5.0)
    rays, R = other.pixel_rays(sensor), other.rotation()
    est = FisheyeEstimator(other.bundle(R, look, sensor))
    t = other.utc_midnight(2025, 12, 21) + 15.0 * 3600.0
    img, truth = other.render(look, t, rays, R, np.random.default_rng(int(t)), sensor)
    assert 18.0 < truth["el_deg"] < 19.0
    uv, _ = est.lens.project((est.R.T @ truth["sun_enu"])[None, :])
    grey = glare_channel(img)
    fit = fit_glare(
        grey, est.lens, *uv[0], 30.0, float(grey.max()), est.options.glare,
        up_cam=est.up_cam, radiometry=est.radiometry,
    )  # fmt: skip
    assert fit is not None and fit.sky_gap and fit.max_gap_deg > 90.0
    assert fit.sky_move_deg > 2.0 * fit.sky_harmonic_deg > 0.2
    # sigma with the sky's share and without it: the difference is that share of the move
    sigmas = []
    for share in (0.5, 0.0):
        opts = replace(FisheyeOptions(), sky_sigma_share=share, max_sigma_deg=5.0)
        res = FisheyeEstimator(other.bundle(R, look, sensor), opts).estimate_image(img, t)
        assert res.found
        sigmas.append(res.sigma_deg)
    assert np.sqrt(sigmas[0] ** 2 - sigmas[1] ** 2) == pytest.approx(0.5 * fit.sky_move_deg, rel=0.1)
