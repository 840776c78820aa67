"""Clouds and distractors on the third renderer (benchmarks.fisheye_third_clouds): a thick
puff hides the sun, a thin edge next to it saturates, the aircraft glint moves at its rate,
the scorer's counts, and the default pipeline on one cloudy frame."""

import math

import numpy as np
import pytest

from benchmarks import fisheye_third_clouds as clouds
from benchmarks.summary_fisheye import fisheye_third_clouds as summary_rows
from controller.calibration.fisheye_bundle import fisheye_bundle_from_dict
from controller.vision.fisheye import FisheyeEstimator, FisheyeResult


@pytest.fixture(scope="module")
def scene():
    return clouds.CloudyScene()


def _sun_px(scene, s):
    u, v = scene.sun_uv(s)
    return round(v), round(u)


def test_a_sun_behind_a_thick_puff_is_hidden_and_its_glare_is_not_saturated(scene):
    az, el = 300.0, 35.0
    s = clouds.sun_enu(az, el)
    gamma = np.degrees(np.arccos(np.clip(scene.d_enu @ s, -1, 1)))
    near = scene.sky & (gamma < 3.0)
    scene.set_sequence(None)
    assert scene.render_linear(s)[near].max() > 1.0  # in the clear, the glare saturates there
    x, y = clouds.layer_xy(s)
    scene.set_sequence(clouds.CloudLayer([(x, y, 1500.0, 10.0)], (0.0, 0.0), 0.75, 0.0))
    truth = scene.truth(0.0, az, el)
    assert truth["visibility"] == "hidden"
    assert truth["transmittance"] == pytest.approx(math.exp(-10.0), rel=0.01)
    assert scene.render_linear(s)[near].max() < 0.5
    img, _ = scene.frame(0.0, az, el)
    v, u = _sun_px(scene, s)
    assert img[v - 5 : v + 6, u - 5 : u + 6].max() < 255


def test_a_thin_cloud_edge_2_to_3_deg_from_the_sun_saturates(scene, monkeypatch):
    """A tau ~ 1 edge 2.5-3 deg from a clear sun (the darkest grey drawn, 0.6; the glare alone
    saturates out to 2 deg): saturated with the forward scattering, not without it (the sky
    behind and the glare alone stay under full scale there)."""
    az, el = 300.0, 55.0
    s = clouds.sun_enu(az, el)
    edge = clouds.sun_enu(az + 2.75 / math.cos(math.radians(el)), el)  # 2.75 deg off, level
    sigma = 200.0
    p_sun, p_edge = clouds.layer_xy(s), clouds.layer_xy(edge)
    out = (p_edge - p_sun) / np.linalg.norm(p_edge - p_sun)
    centre = p_edge + out * sigma * math.sqrt(2 * math.log(15.0))  # tau = 1 at the edge
    scene.set_sequence(clouds.CloudLayer([(*centre, sigma, 15.0)], (0.0, 0.0), 0.6, 0.0))
    assert scene.truth(0.0, az, el)["transmittance"] > 0.7
    tau = scene.tau_px(0.0)
    gamma = np.degrees(np.arccos(np.clip(scene.d_enu @ s, -1, 1)))
    ring = scene.sky & (gamma > 2.5) & (gamma < 3.0) & (tau > 0.8) & (tau < 1.25)
    assert ring.sum() >= 2
    assert scene.render_linear(s)[ring].min() > 1.0
    monkeypatch.setattr(clouds, "FORWARD_3DEG", 0.0)
    assert scene.render_linear(s)[ring].max() < 1.0


def test_the_aircraft_glint_moves_half_a_degree_a_second(scene):
    t0 = 1.77e9
    glints = clouds.random_glints(t0, t0 + 7200.0, np.random.default_rng(5))
    assert len(glints) == 4
    g = glints[0]
    assert g.direction(g.t_on - 1.0) is None and g.direction(g.t_on + clouds.GLINT_S + 1.0) is None
    scene.set_sequence(None, (g,), distractors=True)
    s = clouds.sun_enu(80.0, 20.0)
    base = scene.distractors(s, 1.0, g.t_on - 10.0)  # reflection and ghost, no glint
    rays = []
    for dt in (40.0, 70.0):
        d = g.direction(g.t_on + dt)
        assert d[2] > 0
        spot = scene.distractors(s, 1.0, g.t_on + dt) - base
        v, u = np.unravel_index(np.argmax(spot[..., 1]), spot.shape[:2])
        assert spot[v, u, 1] > 1.0  # saturated at its centre
        assert clouds.angle_deg(scene.d_enu[v, u], d) < 0.6  # drawn where it is
        rays.append(scene.d_enu[v, u])
    moved = clouds.angle_deg(g.direction(g.t_on + 40.0), g.direction(g.t_on + 70.0))
    assert moved == pytest.approx(15.0, abs=1e-6)
    assert clouds.angle_deg(*rays) == pytest.approx(15.0, abs=1.0)  # between the drawn spots


def _truth(label, az=100.0, el=30.0, T=1.0):
    return {
        "visibility": label,
        "sun_enu": clouds.sun_enu(az, el),
        "transmittance": T,
        "az_deg": az,
        "el_deg": el,
    }


def _found(az, el):
    return FisheyeResult(image=None, found=True, az_deg=az, el_deg=el, sigma_deg=0.1)


def _lost(reason="irregular_glare"):
    return FisheyeResult(image=None, found=False, reason=reason)


def test_the_scorer_counts_false_detections_and_misses_and_neither_for_a_dimmed_sun():
    sc = clouds.Scorer()
    frames = [
        (_found(100.0, 30.0), _truth("hidden", T=0.01)),  # found while hidden: false
        (_lost(), _truth("visible")),  # a miss
        (_lost("no_rim"), _truth("dimmed", T=0.5)),  # neither
        (_found(100.0, 30.3), _truth("dimmed", T=0.5)),  # correct, not in the visible RMS
        (_found(100.0, 31.5), _truth("visible")),  # 1.5 deg off: false
        (_found(100.0, 30.1), _truth("visible")),  # correct, 0.1 deg
        (_lost(), _truth("hidden", T=0.0)),  # correct rejection
    ]
    for i, (res, truth) in enumerate(frames):
        sc.add("seq", 1.77e9 + 30 * i, res, truth)
    r = sc.summary()
    c = r["total"]["counts"]
    assert (c["false_detection"], c["miss"], c["dimmed_not_found"]) == (2, 1, 1)
    assert (c["correct_detection"], c["correct_rejection"], c["visible"]) == (2, 1, 3)
    assert r["total"]["error_where_visible"]["n"] == 1
    assert r["total"]["error_where_visible"]["rms_deg"] == pytest.approx(0.1, abs=1e-3)
    assert r["total"]["miss_reasons"] == {"irregular_glare": 1}
    assert [(k["kind"], k["label"]) for k in sc.cases] == [
        ("false_detection", "hidden"),
        ("miss", "visible"),
        ("false_detection", "visible"),
    ]
    assert sc.cases[1]["reason"] == "irregular_glare"
    assert sc.cases[2]["error_deg"] == pytest.approx(1.5, abs=1e-3)
    assert r["false_detections_on_a_hidden_sun"] == 1
    assert r["acceptance"] == {
        "zero_false_detections": False,
        "misses_le_5pct": False,
        "visible_rms_le_0.2": True,
    }
    rows = summary_rows({"passes": {"with site": r}})
    assert [(h.value, h.ok) for h in rows] == [
        ("2 (1 within 1 deg of a hidden sun; 7 frames)", False),
        ("33.3 % (1 of 3)", False),
        ("0.1 deg (found 1 of 3)", True),
    ]


#: a frame of the 0.3-coverage sequence: the sun visible, broken cloud around it
CLOUDY_FRAME = 216


def _visible_frame(scene, index: int):
    """Frame ``index`` of sequence 0 (2 h, every 30 s), its time and truth; its sun visible."""
    seq = clouds.SEQUENCES[0]
    frames = clouds.frame_times(seq, 2.0, 30.0)
    clouds.set_up(scene, seq, frames[0][0], frames[-1][0])
    t, az, el = frames[index]
    img, truth = scene.frame(t, az, el)
    assert truth["visibility"] == "visible"
    return img, t, truth


def test_the_default_pipeline_finds_a_visible_sun_in_a_cloudy_frame(scene):
    img, t, truth = _visible_frame(scene, CLOUDY_FRAME)
    gamma = np.degrees(np.arccos(np.clip(scene.d_enu @ truth["sun_enu"], -1, 1)))
    tau = scene.tau_px(t)
    assert (tau[scene.sky] > clouds.COVER_TAU).mean() > 0.2  # a cloudy sky
    assert ((tau > clouds.COVER_TAU) & scene.sky & (gamma < 20.0)).any()  # cloud near the sun
    est = FisheyeEstimator(fisheye_bundle_from_dict(clouds.bundles()["with site"]))
    res = est.estimate_image(img, t)
    assert res.found, res.reason
    assert clouds.angle_deg(clouds.sun_enu(res.az_deg, res.el_deg), truth["sun_enu"]) < 0.2


#: a sun 27 deg up whose rings a thick cloud's edge crosses (sequence 0's frame 105)
CLOUD_IN_THE_RINGS = 105


def test_a_clouds_edge_in_the_rings_no_longer_pulls_the_sun_with_the_site(scene):
    """The sky models had read the cloud's edge as the sky's gradient and carried it to the
    rim: 0.83 deg off, towards the cloud.  Left out of them (``clearsky.cloud_edges``, on
    with the site), 0.07 (both with the CCD's smear left in, as before it was taken off with
    the site too).  As shipped, the smear taken off as well: 0.14, where without the cloud's
    edges left out the fix is 1.02 deg off and the ephemeris gate refuses it."""
    from dataclasses import replace

    img, t, truth = _visible_frame(scene, CLOUD_IN_THE_RINGS)
    bundle = fisheye_bundle_from_dict(clouds.bundles()["with site"])
    errors = {}
    for edges in (True, False):
        est = FisheyeEstimator(bundle)
        assert est.options.glare.cloud_edges and est.options.glare.column_smear  # the site turns them on
        est.options = replace(
            est.options, glare=replace(est.options.glare, cloud_edges=edges, column_smear=False)
        )
        res = est.estimate_image(img, t)
        assert res.found, res.reason
        errors[edges] = clouds.angle_deg(clouds.sun_enu(res.az_deg, res.el_deg), truth["sun_enu"])
    assert errors[True] < 0.15 < 0.5 < errors[False], errors
    shipped = FisheyeEstimator(bundle).estimate_image(img, t)
    assert shipped.found, shipped.reason
    assert clouds.angle_deg(clouds.sun_enu(shipped.az_deg, shipped.el_deg), truth["sun_enu"]) < 0.3


#: sequence 0: a sun 21.3 deg up in the clear, whose rings a cloud's edge crosses
RINGS_ACROSS_A_CLOUD = 1797852240.0


def test_the_rings_leave_a_clouds_edge_out_and_place_the_sun(scene, monkeypatch):
    """The rings' fix (``rings.ring_direction``) reads the rings as the sky models do: with
    the cloud's edge left out (``clearsky.cloud_edges``, on with the site) they are a clear
    sky's (roughness 0.24; 16 % of the samples left out) and place the sun 0.025 deg off,
    where its rim reads it 0.24 deg low; read whole, the cloud makes them rough (1.49, the
    limit 0.35) and they place nothing (the rim alone, before)."""
    from dataclasses import replace

    from controller.vision.fisheye.locator import LocatorChoice
    from controller.vision.fisheye.rings import ring_direction

    seq = clouds.SEQUENCES[0]
    frames = clouds.frame_times(seq, 2.0, 30.0)
    clouds.set_up(scene, seq, frames[0][0], frames[-1][0])
    t, az, el = next(f for f in frames if f[0] == RINGS_ACROSS_A_CLOUD)
    img, truth = scene.frame(t, az, el)
    assert truth["visibility"] == "visible"
    est = FisheyeEstimator(fisheye_bundle_from_dict(clouds.bundles()["with site"]))
    seen, place = [], LocatorChoice.place

    def spy(self, cand, *args, **kw):
        seen.append((cand.fit.sky_reading, cand.d_cam))
        return place(self, cand, *args, **kw)

    monkeypatch.setattr(LocatorChoice, "place", spy)
    assert est.estimate_image(img, t).found
    (reading, rim), up = seen[-1], est.up_cam
    sun = est.R.T @ truth["sun_enu"]
    fix = ring_direction(reading, up)
    assert fix is not None and clouds.angle_deg(fix, sun) < 0.05 < 0.2 < clouds.angle_deg(rim, sun)
    rays = np.cos(reading.phi)[:, None, None] * reading.e1 + np.sin(reading.phi)[:, None, None] * reading.e2
    d = np.cos(reading.chi)[None, :, None] * reading.axis + np.sin(reading.chi)[None, :, None] * rays
    whole = replace(reading, sky=d @ up > math.sin(math.radians(1.0)))  # every sample of the sky
    assert (whole.sky & ~reading.sky).sum() > 0.05 * whole.sky.sum()  # the cloud's edge, left out
    assert ring_direction(whole, up) is None


#: the distractors' sequence: a thin cloud's lobe on the rim of a 19.5-deg sun (clear line
#: of sight), where the rings refuse to place it even with the cloud's edge left out
LOBE_ON_THE_RIM = (1774009410.0, 1774009440.0, 1774009470.0)


def test_where_the_rings_refuse_a_cloudy_sun_the_rim_is_moved_by_its_offset_from_them(scene, monkeypatch):
    """The third renderer's sky is a product: its rim reads a sun near 20 deg some 0.2 deg
    low, its rings right, and the camera, with the site, chooses the rings on clear frames.
    Under a thin cloud's lobe the rings, its edge left out, are still too rough to place
    the sun, and the rim (lower still) is moved by its median offset from the rings' fixes near that elevation (0.50, 0.49,
    0.48 deg off as it reads; 0.28, 0.28, 0.26 moved)."""
    from controller.vision.fisheye import locator

    seq = clouds.SEQUENCES[3]
    frames = clouds.frame_times(seq, 2.0, 30.0)
    clouds.set_up(scene, seq, frames[0][0], frames[-1][0])
    clouds_on = scene.clouds
    clear = [f for f in frames[::10] if 17.0 < f[2] < 22.0]
    lobe = [f for f in frames if f[0] in LOBE_ON_THE_RIM]
    assert len(clear) >= 4 and len(lobe) == 3
    scene.set_sequence(None, seed=seq.seed)
    taught = [scene.frame(*f) for f in clear]
    scene.set_sequence(clouds_on, distractors=True, seed=seq.seed)
    cloudy = [scene.frame(*f) for f in lobe]
    assert all(truth["visibility"] == "visible" for _, truth in cloudy)
    bundle = fisheye_bundle_from_dict(clouds.bundles()["with site"])
    errors, shipped = {}, locator.MIN_OFFSETS
    for min_offsets in (shipped, 10**6):  # as shipped; the rim left as it reads
        monkeypatch.setattr(locator, "MIN_OFFSETS", min_offsets)
        est = FisheyeEstimator(bundle)
        for (img, _), (t, _, _) in zip(taught, clear):
            assert est.estimate_image(img, t).found
        assert est.locator is not None and est.locator.rings
        out = []
        for (img, truth), (t, _, _) in zip(cloudy, lobe):
            res = est.estimate_image(img, t)
            assert res.found, res.reason
            assert ("rim_by_rings" in res.quality) == (min_offsets == shipped)
            out.append(clouds.angle_deg(clouds.sun_enu(res.az_deg, res.el_deg), truth["sun_enu"]))
        errors[min_offsets] = out
    for moved, left in zip(errors[shipped], errors[10**6]):
        assert moved < left - 0.1


def test_a_dimmed_sun_minutes_after_the_last_anchor_is_not_vouched_for_by_a_wide_sequence_gate(scene):
    """Without the site, a fresh camera: the sun of the Dec 21 afternoon sequence is found on
    two frames 30 s apart (anchors), then dimmed (T 0.5-0.8) for minutes, its rims bent by
    the cloud, the sequence gate grown to several degrees.  Such a gate vouches for little:
    a rim must hold on 70 % of its rays, as with no gate.  Which frames give such a weak rim
    depends on the last bits of the floating point: with numpy's AVX-512 kernels off (an
    AVX2 machine), the frame at T 0.49 holds on 56 %, 1.53 deg from the sun, and the wide
    gate took it (a false detection); with them on, one at T 0.62 holds on 53 %, 0.24 deg
    from the sun.  So over the half hour around it: the wide gate alone takes a weak rim
    that the rule refuses, and the rule leaves no fix more than 1 deg from the sun."""
    from dataclasses import replace

    from controller.vision.fisheye import FisheyeOptions
    from controller.vision.fisheye.gates import GateOptions

    seq = next(s for s in clouds.SEQUENCES if s.name == "broken cloud 0.7, Dec 21 afternoon")
    frames = clouds.frame_times(seq, 2.0, 30.0)
    clouds.set_up(scene, seq, frames[0][0], frames[-1][0])
    t_false = 1797887820.0
    todo = [f for f in frames if t_false - 900.0 <= f[0] <= t_false + 600.0]
    bundle = fisheye_bundle_from_dict(clouds.bundles()["without site"])
    ests = {
        "now": FisheyeEstimator(bundle),
        "before": FisheyeEstimator(
            bundle,
            FisheyeOptions(
                gates=replace(
                    GateOptions(), sequence_vouch_max_deg=math.inf, self_vouched_max_sigma_deg=math.inf
                )
            ),
        ),
    }
    unvouched, worst = [], 0.0
    for t, az, el in todo:
        img, truth = scene.frame(t, az, el)
        now, before = (e.estimate_image(img, t) for e in ests.values())
        if now.found:
            worst = max(worst, clouds.angle_deg(clouds.sun_enu(now.az_deg, now.el_deg), truth["sun_enu"]))
        if not now.found and now.reason == "unvouched_glare" and "rim_share" in now.extra:  # not its sigma
            assert now.extra["rim_share"] < 0.7
            unvouched.append(before)
    assert unvouched and all(b.found and b.quality[0] == "gate_sequence" for b in unvouched)
    assert worst < 1.0
