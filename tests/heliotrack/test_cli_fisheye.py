"""``heliotrack calibrate fisheye`` and ``heliotrack estimate --sensor fisheye`` end to end."""

import json
import math
import shutil
import subprocess
import sys

import numpy as np
import pytest

from controller.sun.types import angle_between_deg, azel_to_enu
from heliotrack.cli import main
from hil.skycam import sky_profile
from hil.skycam.dataset import write_dataset

HELIOTRACK = [sys.executable, "-m", "heliotrack.cli"]


@pytest.fixture(scope="module")
def installed(tmp_path_factory):
    """An installer's folder rendered by the HIL, calibrated through the CLI."""
    out = tmp_path_factory.mktemp("sky")
    truth = write_dataset(sky_profile("seed"), out, step_min=45, n_boards=24)
    bundle = out / "sky.toml"
    assert (
        main(
            [
                "calibrate",
                "fisheye",
                "lens",
                "--square",
                "0.04",
                "--bundle",
                str(bundle),
                *map(str, sorted((out / "checkerboards").glob("*.png"))),
            ]
        )
        == 0
    )
    site = truth["site"]
    assert (
        main(
            [
                "calibrate",
                "fisheye",
                "orientation",
                "--lat",
                str(site["latitude"]),
                "--lon",
                str(site["longitude"]),
                "--alt",
                str(site["altitude"]),
                "--horizon",
                str(out / "horizon.png"),
                "--bundle",
                str(bundle),
                *map(str, sorted((out / "day").glob("*.png"))),
            ]
        )
        == 0
    )
    return out, bundle, truth


def lines(capsys):
    return [json.loads(x) for x in capsys.readouterr().out.splitlines() if x.strip()]


def test_calibration_writes_a_fisheye_bundle_with_orientation_and_site(installed):
    _out, bundle, truth = installed
    text = bundle.read_text()
    assert 'model = "fisheye"' in text and "[orientation]" in text and "[site]" in text
    from controller.calibration.fisheye_bundle import load_fisheye_bundle

    b = load_fisheye_bundle(bundle)
    R_true = np.asarray(truth["enu_from_camera"])
    ang = math.degrees(math.acos(np.clip((np.trace(b.enu_from_camera @ R_true.T) - 1) / 2, -1, 1)))
    assert ang < 0.1
    assert b.orientation.method == "sun+horizon+lens"


def test_estimate_prints_one_line_per_image_in_time_order(installed, capsys):
    out, bundle, truth = installed
    frames = sorted((out / "day").glob("*.png"))[2:6]
    assert main(["estimate", "--sensor", "fisheye", "--calib", str(bundle), *map(str, reversed(frames))]) == 0
    got = lines(capsys)
    assert [g["image"] for g in got] == [str(p) for p in frames]
    by_name = {f["image"].split("/")[-1]: f for f in truth["frames"]}
    for g in got:
        assert g["found"] and g["frame"] == "enu" and g["time"].endswith("Z")
        t = by_name[g["image"].split("/")[-1]]
        err = float(
            angle_between_deg(azel_to_enu(g["az_deg"], g["el_deg"]), azel_to_enu(t["az_deg"], t["el_deg"]))
        )
        assert err < 0.1
        assert {"quality", "sigma_deg", "offset_px", "radius_deg"} <= set(g)


def test_estimate_seed_algorithm(installed, capsys):
    out, bundle, _ = installed
    frames = sorted((out / "day").glob("*.png"))[1:4]
    assert (
        main(
            [
                "estimate",
                "--sensor",
                "fisheye",
                "--algorithm",
                "seed",
                "--calib",
                str(bundle),
                *map(str, frames),
            ]
        )
        == 0
    )
    got = lines(capsys)
    assert all(g["algorithm"] == "seed" for g in got) and any(g["found"] for g in got)
    assert all("offset_px" in g for g in got if g["found"])


def test_bad_files_give_found_false_with_a_reason(installed, capsys, tmp_path):
    out, bundle, _ = installed
    good = sorted((out / "day").glob("*.png"))[3]
    trunc = tmp_path / "2025-03-20T06-00-00Z.png"
    trunc.write_bytes(good.read_bytes()[:5000])
    empty = tmp_path / "empty.png"
    empty.write_bytes(b"")
    text = tmp_path / "notes.png"
    text.write_text("hello")
    small = tmp_path / "small.png"
    import cv2

    cv2.imwrite(str(small), np.zeros((48, 64, 3), np.uint8))
    assert (
        main(
            [
                "estimate",
                "--sensor",
                "fisheye",
                "--calib",
                str(bundle),
                str(trunc),
                str(empty),
                str(text),
                str(small),
            ]
        )
        == 0
    )
    got = {g["image"].split("/")[-1]: g for g in lines(capsys)}
    assert {k: (g["found"], g["reason"]) for k, g in got.items()} == {
        trunc.name: (False, "truncated_file"),
        "empty.png": (False, "empty_file"),
        "notes.png": (False, "undecodable_image"),
        "small.png": (False, "size_mismatch"),
    }


def test_a_hotspot_bundle_is_a_clear_error_for_the_fisheye_sensor(tmp_path):
    from pathlib import Path

    hotspot = Path(__file__).resolve().parents[2] / "config" / "calibration" / "seed.toml"
    local = tmp_path / "seed.toml"
    shutil.copy(hotspot, local)
    r = subprocess.run(
        [*HELIOTRACK, "estimate", "--sensor", "fisheye", "--calib", str(local), str(local)],
        check=False,
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2 and "Traceback" not in r.stderr
    assert str(local) in r.stderr and "camera" in r.stderr


def test_level_prints_the_tilt(installed, capsys):
    out, bundle, _ = installed
    assert main(["calibrate", "fisheye", "level", "--bundle", str(bundle), str(out / "horizon.png")]) == 0
    (g,) = lines(capsys)
    assert g["tilt_deg"] == pytest.approx(0.8, abs=0.15) and g["disagreement_with_orientation_deg"] < 0.2
