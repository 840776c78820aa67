"""The whole calibration chain from rendered images alone, through the CLI, on a half-size
camera (fast); the truth is used only to check the result."""

import json

import pytest

from controller.calibration.bundle import load_bundle
from controller.sun.types import angle_between_deg
from hil.camera.dataset import write_dataset
from tests.controller.vision.helpers import small_scenario


@pytest.fixture(scope="module")
def dataset(tmp_path_factory):
    scn = small_scenario(noise=True, scale=0.5, tilt_deg=0.3)
    out = tmp_path_factory.mktemp("install")
    write_dataset(scn, out, step_min=45, n_boards=8, scan_points=20000)
    return scn, out


@pytest.mark.parametrize("method", ["ephemeris-full", "noon"])
def test_calibrate_all_recovers_the_installation(dataset, method, capsys):
    from heliotrack.cli import main

    scn, folder = dataset
    bpath = folder / f"bundle-{method}.toml"
    rc = main(
        [
            "calibrate",
            "all",
            str(folder),
            "--lat",
            "32.4835",
            "--lon",
            "48.3364",
            "--method",
            method,
            "--bundle",
            str(bpath),
        ]
    )
    assert rc == 0
    steps = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    assert steps[0]["step"] == "intrinsics" and steps[0]["rms_px"] < 0.3
    b = load_bundle(bpath)
    assert abs(b.camera.fx - scn.camera.fx) / scn.camera.fx < 0.005
    assert abs(b.surface.radius - scn.globe.radius) < 2e-4
    # half-size camera: the pose is good to ~0.2 deg, and the zenith expressed in the model
    # frame inherits that error (the full ephemeris fit absorbs it on purpose)
    assert angle_between_deg(b.zenith(), scn.zenith_model) < 0.6
    # the bundle estimates the sun in ENU on a day it was not calibrated on
    from controller.vision import HotspotEstimator
    from hil.camera import render_frame
    from tests.controller.vision.helpers import utc

    est = HotspotEstimator(b)
    for t in (utc(2025, 6, 21, 6, 0), utc(2025, 12, 21, 9, 0)):
        fr = render_frame(scn, t)
        r = est.estimate_image(fr.image, t)
        assert r.found and r.frame == "enu"
        from controller.sun.types import azel_to_enu

        assert angle_between_deg(azel_to_enu(r.az_deg, r.el_deg), fr.truth["sun_enu"]) < 0.5


def test_an_ephemeris_method_without_the_site_says_it_falls_back_to_noon(dataset, capsys):
    from heliotrack.cli import main

    _, folder = dataset
    bpath = folder / "bundle-nosite.toml"
    assert main(["calibrate", "all", str(folder), "--method", "ephemeris-full", "--bundle", str(bpath)]) == 0
    steps = [json.loads(x) for x in capsys.readouterr().out.splitlines()]
    notes = [s["note"] for s in steps if "note" in s]
    assert notes == ["ephemeris-full asked, no --lat/--lon: the paper's noon culmination instead"]
    assert any(s.get("method") == "noon" for s in steps)
