"""The fourth renderer (benchmarks.fisheye_fourth*): its lens as the bundle hands it over,
where it draws the sun, its exposure and truth, the pipeline on one of its frames, and the
bench's rows."""

import ast
import math
from dataclasses import replace
from datetime import datetime
from pathlib import Path

import cv2
import numpy as np
import pytest

from benchmarks import fisheye_fourth as fourth
from benchmarks.fisheye_fourth_scene import FourthScene
from benchmarks.fisheye_fourth_world import CloudSpec, Look, clear_times, cloud_sequences, lens_r_unit
from benchmarks.summary_fisheye import fisheye_fourth as summary_rows
from controller.calibration.fisheye_bundle import fisheye_bundle_from_dict
from controller.vision.fisheye import FisheyeEstimator

DARK = Look("zenith grey 5", 640, 480, 5.0)
SMALL = Look("zenith grey 5, small", 320, 240, 5.0)  # the same lens and sky, four times faster


def _kd(scene):
    c = fisheye_bundle_from_dict(scene.bundle()).camera
    return np.array([[c.fx, 0.0, c.cx], [0.0, c.fy, c.cy], [0.0, 0.0, 1.0]]), np.array(c.dist)


@pytest.mark.parametrize("look", [DARK, Look("hd", 1280, 960, 5.0)], ids=["640x480", "1280x960"])
def test_the_bundles_kb_fit_reproduces_the_true_lens(look):
    scene = FourthScene(look)
    K, D = _kd(scene)
    th = np.radians(np.linspace(0.0, 92.0, 400))
    td = th * (1 + D[0] * th**2 + D[1] * th**4 + D[2] * th**6 + D[3] * th**8)
    assert np.abs(K[0, 0] * td - scene.f * lens_r_unit(th)).max() < 0.05  # px
    # and through OpenCV with the bundle's rotation, all round the sky
    az, el = np.meshgrid(np.arange(0.0, 360.0, 40.0), [10.0, 35.0, 60.0, 85.0])
    s = np.stack([np.cos(np.radians(el)) * np.sin(np.radians(az)), np.cos(np.radians(el)) * np.cos(np.radians(az)),
                  np.sin(np.radians(el))], -1).reshape(-1, 3)  # fmt: skip
    M = np.array(scene.bundle()["orientation"]["enu_from_camera"])
    uv = cv2.fisheye.projectPoints((s @ M).reshape(-1, 1, 3), np.zeros(3), np.zeros(3), K, D)[0].reshape(
        -1, 2
    )
    assert np.abs(uv - scene.project(s)).max() < 0.05


def test_the_sun_is_drawn_where_the_bundle_puts_it_and_the_zenith_at_its_grey():
    scene = FourthScene(DARK, site=fourth.SITE)
    t = max(clear_times("2026-12-21", 20.0, site=fourth.SITE), key=lambda t: scene.truth(t)["el_deg"])
    img, truth = scene.frame(t)
    assert img.shape == (480, 640, 3) and img.dtype == np.uint8
    assert truth["el_deg"] > 75 and truth["visibility"] == "visible"
    # the saturated core's centroid (the bloom spills both ways along its columns: no bias)
    g = img.min(axis=2).astype(float)
    u0, v0 = scene.project(truth["sun_enu"])
    win = np.s_[int(v0) - 12 : int(v0) + 13, int(u0) - 12 : int(u0) + 13]
    sat = g[win] >= 250
    vv, uu = np.nonzero(sat)
    assert 5 < sat.sum() < 200
    assert math.hypot(uu.mean() + int(u0) - 12 - u0, vv.mean() + int(v0) - 12 - v0) < 0.5
    zu, zv = scene.project(np.array([0.0, 0.0, 1.0]))
    assert abs(img[int(zv) - 2 : int(zv) + 3, int(zu) - 2 : int(zu) + 3].mean() - 5.0) < 1.5


def test_frames_are_the_same_for_the_same_time_and_seed():
    seq = cloud_sequences()[1]
    a = FourthScene(SMALL, clouds=seq["clouds"], seed=1)
    b = FourthScene(SMALL, clouds=seq["clouds"], seed=1)
    t = clear_times("2026-06-21", 60.0, site=fourth.SITE)[2]
    assert np.array_equal(a.frame(t)[0], b.frame(t)[0])


def test_the_truth_labels_follow_the_beams_transmittance():
    scene = FourthScene(SMALL, site=fourth.SITE, clouds=CloudSpec(0.6, seed=5))
    t0 = clear_times("2026-03-20", 20.0, site=fourth.SITE)[10]
    labels = set()
    for t in t0 + 120.0 * np.arange(40):
        tr = scene.truth(t)
        T, want = tr["transmittance"], "hidden" if tr["transmittance"] < 0.05 else None
        want = want or ("visible" if T >= 0.9 else "dimmed")
        assert tr["visibility"] == want
        labels.add(want)
    assert labels == {"hidden", "dimmed", "visible"}


def test_the_rendering_imports_neither_the_hil_nor_the_controller():
    for mod in ("fisheye_fourth_world.py", "fisheye_fourth_scene.py"):
        tree = ast.parse((Path(fourth.__file__).parent / mod).read_text())
        names = [a.name for n in ast.walk(tree) if isinstance(n, ast.Import) for a in n.names]
        names += [n.module or "" for n in ast.walk(tree) if isinstance(n, ast.ImportFrom)]
        assert not [m for m in names if m.split(".")[0] in ("hil", "controller")]


def test_the_default_pipeline_finds_a_high_sun_of_this_renderer():
    scene = FourthScene(DARK, site=fourth.SITE)
    est = FisheyeEstimator(fisheye_bundle_from_dict(scene.bundle()))
    t = (
        max(clear_times("2026-03-20", 20.0, site=fourth.SITE), key=lambda t: scene.truth(t)["el_deg"])
        - 3600.0
    )
    img, truth = scene.frame(t)
    r = est.estimate_image(img, t)
    assert r.found, r.reason
    s = truth["sun_enu"]
    d = np.array([np.cos(np.radians(r.el_deg)) * np.sin(np.radians(r.az_deg)),
                  np.cos(np.radians(r.el_deg)) * np.cos(np.radians(r.az_deg)), np.sin(np.radians(r.el_deg))])  # fmt: skip
    assert math.degrees(math.acos(min(1.0, float(d @ s)))) < 0.05


def test_a_high_suns_small_glare_that_blooms_up_and_down_is_found():
    """Noon of 20 Mar, 56 deg up: a rim of 4 px whose columns spill a pixel or two up and
    down; measured as a rim it keeps 33 of 48 rays (the small glare's rule wants 80 %), as a
    bloom both ways it is found within 0.02 deg (docs/fisheye.md, step 7)."""
    scene = FourthScene(DARK, site=fourth.SITE)
    est = FisheyeEstimator(fisheye_bundle_from_dict(scene.bundle()))
    t = max(clear_times("2026-03-20", 20.0, site=fourth.SITE), key=lambda t: scene.truth(t)["el_deg"])
    img, truth = scene.frame(t)
    r = est.estimate_image(img, t)
    assert r.found, r.reason
    assert "bloom" in r.quality
    s = truth["sun_enu"]
    d = np.array([np.cos(np.radians(r.el_deg)) * np.sin(np.radians(r.az_deg)),
                  np.cos(np.radians(r.el_deg)) * np.cos(np.radians(r.az_deg)), np.sin(np.radians(r.el_deg))])  # fmt: skip
    assert math.degrees(math.acos(min(1.0, float(d @ s)))) < 0.02


def test_a_wide_fix_that_only_the_cameras_own_fixes_vouch_for_is_not_reported():
    """The broken cloud of a winter noon, without the site: at 09:32:30 a cloud's glow cuts the
    sun's rim, and the fix behind the sequence's own gate alone lies 1.07 deg off with a sigma
    of 0.55. No gate holds it within 1 deg of the sun, and its sigma does not either at 3
    sigma: it is refused (``unvouched_glare``), where the fixes before it are reported."""
    i, seq = next((i, s) for i, s in enumerate(cloud_sequences()) if s["name"] == "winter_noon_c40")
    scene = FourthScene(fourth.CLOUD_LOOK, site=fourth.SITE, clouds=seq["clouds"], distractors=seq["distractors"], seed=i)  # fmt: skip
    b = fisheye_bundle_from_dict(scene.bundle())
    est = FisheyeEstimator(replace(b, site=None))
    t0 = datetime.fromisoformat(seq["start_utc"]).timestamp()
    rs, suns = [], []
    for t in t0 + 30.0 * np.arange(6):
        img, truth = scene.frame(float(t))
        rs.append(est.estimate_image(img, float(t)))
        suns.append(truth["sun_enu"])
    assert any(r.found for r in rs[:5])  # the sequence's gate has its anchors (09:30:30, 09:31:30)
    for r, s in zip(rs, suns, strict=True):
        if r.found:  # each within 1 deg of the sun: no false detection
            d = np.array([np.cos(np.radians(r.el_deg)) * np.sin(np.radians(r.az_deg)),
                          np.cos(np.radians(r.el_deg)) * np.cos(np.radians(r.az_deg)), np.sin(np.radians(r.el_deg))])  # fmt: skip
            assert math.degrees(math.acos(min(1.0, float(d @ s)))) < 1.0
    assert not rs[5].found and rs[5].reason == "unvouched_glare"


def _score(rms, found=90, false=0):
    return {"n_frames": 100, "found": found, "false_detections": false, "error": {"rms_deg": rms}}


def _pass(false, miss, rms):
    ok = {"zero_false_detections": false == 0, "misses_le_5pct": miss <= 5, "visible_rms_le_0.2": rms <= 0.2}
    return {
        "total": {
            "counts": {
                "false_detection": false,
                "frames": 900,
                "miss_rate_of_visible": miss / 100,
                "miss": miss,
                "visible": 100,
            },  # fmt: skip
            "error_where_visible": {"rms_deg": rms, "n": 100 - miss},
        },
        "false_detections_on_a_hidden_sun": 0,
        "acceptance": ok,
    }


def test_summary_rows_judge_each_look_by_its_size_and_each_cloud_pass():
    small, big = fourth.LOOKS[0], fourth.LOOKS[1]
    r = {
        "looks": {k.name: {"target_deg": fourth.target_deg(k)} for k in (small, big)},
        "clear": {
            small.name: {**_score(0.025), "without_site": _score(0.025, false=1)},
            big.name: {**_score(0.025), "without_site": _score(0.015)},
        },
        "clouds": {
            "look": small.name,
            "passes": {"with site": _pass(0, 3, 0.15), "without site": _pass(2, 9, 0.25)},
        },
        "acceptance": {},
    }
    r["acceptance"] = {
        f"{k}: {site}": ok
        for k, oks in ((small.name, (True, False)), (big.name, (False, True)))
        for site, ok in zip(("with site", "without site"), oks)
    }
    rows = {h.figure: h for h in summary_rows(r)}
    assert rows[f"{small.name}: clear-sky RMS, with site"].ok is True
    assert rows[f"{small.name}: clear-sky RMS, without site"].ok is False  # a false detection
    assert rows[f"{big.name}: clear-sky RMS, with site"].target == "<= 0.02 deg"
    assert rows[f"{big.name}: clear-sky RMS, with site"].ok is False
    cloud = f"broken cloud ({small.name}): "
    assert rows[cloud + "misses of a visible sun, with site"].ok is True
    assert rows[cloud + "false detections, without site"].ok is False
    assert rows[cloud + "RMS where visible, without site"].value.startswith("0.25")


def test_a_quick_clear_run_scores_both_cameras():
    r = fourth.run_clear(SMALL, days=("2026-12-21",), step_min=120.0)
    assert r["n_frames"] == r["without_site"]["n_frames"] >= 5
    assert r["found"] >= 2 and r["false_detections"] == 0
