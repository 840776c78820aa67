"""``heliotrack calibrate fisheye mount``: a panel camera's rotation on its panel from
rendered commissioning frames (the world's panel camera, mounted off the normal) and the
panel's true angles."""

from __future__ import annotations

import json
import shutil
from datetime import UTC, datetime

import numpy as np
import pytest

from controller.calibration.fisheye_bundle import load_fisheye_bundle
from heliotrack.cli import main
from hil.camera import Site
from hil.panelcam import PanelCamera, panel_from_camera, write_commissioning
from tests.conftest import REPO

PLANT = REPO / "config" / "hil-closedloop-offset.toml"
LENS = REPO / "config" / "calibration" / "panel-fisheye.toml"
HELD = {
    "row-1": [[-40.0], [-20.0], [0.0], [20.0], [40.0]],
    "dual-1": [[120.0, 40.0], [180.0, 60.0], [240.0, 40.0]],
}
MOUNT = {"row-1": (0.0, 0.8, 0.0), "dual-1": (0.5, 0.7, 0.0)}


@pytest.fixture(scope="module")
def commissioning(tmp_path_factory):
    """Per tracker: frames every 30 min of a clear day with the panel held at a few angles,
    and an inclinometer's log of those angles (0.02 deg of noise)."""
    out = tmp_path_factory.mktemp("mount")
    start = datetime(2024, 3, 21, 4, 0, tzinfo=UTC).timestamp()
    for name, held in HELD.items():
        kind = "single-axis" if name.startswith("row") else "dual-axis"
        cam = PanelCamera(kind, Site(32.4835, 48.3364, 150.0), axis_azimuth=180.0, mount_deg=MOUNT[name])
        write_commissioning(cam, out / name, held, start=start, frames=18, step_s=1800.0)
    return out


def calibrate(folder, name, bundle, *extra, frames_of=None):
    frames = folder / (frames_of or name)
    return main(
        [
            "calibrate",
            "fisheye",
            "mount",
            "--config",
            str(PLANT),
            "--tracker",
            name,
            "--angles",
            str(frames / "angles.csv"),
            "--bundle",
            str(bundle),
            *extra,
            *map(str, sorted(frames.glob("*.png"))),
        ]
    )


@pytest.mark.parametrize("name", ["row-1", "dual-1"])
def test_the_mount_is_fitted_and_written_into_the_lens_bundle(commissioning, tmp_path, capsys, name):
    bundle = shutil.copy(LENS, tmp_path / "lens.toml")
    assert calibrate(commissioning, name, bundle) == 0
    out = json.loads(capsys.readouterr().out)
    assert out["used"] >= 12 and out["residual_deg"] < 0.1
    np.testing.assert_allclose(out["rotvec_deg"][:2], MOUNT[name][:2], atol=0.08)
    b = load_fisheye_bundle(bundle)
    truth = panel_from_camera(MOUNT[name])
    normal_err = np.degrees(np.arccos(np.clip((b.mount.matrix.T @ [0, 0, 1]) @ (truth.T @ [0, 0, 1]), -1, 1)))
    assert normal_err < 0.06
    assert b.mount.method == "sun+panel angles" and b.camera == load_fisheye_bundle(LENS).camera


def test_input_errors_are_one_line_and_keep_the_bundle(commissioning, tmp_path, capsys):
    bundle = shutil.copy(LENS, tmp_path / "lens.toml")
    before = bundle.read_bytes()
    assert calibrate(commissioning, "row-9", bundle, frames_of="row-1") == 2
    assert "--tracker: expected a tracker of" in capsys.readouterr().err
    bad = tmp_path / "bad"
    shutil.copytree(commissioning / "row-1", bad / "row-1")
    (bad / "row-1" / "angles.csv").write_text("time,azimuth\n2024-03-21T04:00:00Z,1\n")
    assert calibrate(bad, "row-1", bundle) == 2
    assert "missing column(s) rotation" in capsys.readouterr().err
    (bad / "row-1" / "angles.csv").write_text("time,rotation\n2020-01-01T00:00:00Z,1\n")
    assert calibrate(bad, "row-1", bundle) == 2
    err = capsys.readouterr().err
    assert "the sun found in 0 of 18" in err and "no panel angle within 5 s" in err
    assert bundle.read_bytes() == before
    sky = tmp_path / "sky.toml"
    sky.write_text(
        LENS.read_text() + "\n[orientation]\nenu_from_camera = [[1, 0, 0], [0, 1, 0], [0, 0, 1]]\n"
    )
    assert calibrate(commissioning, "row-1", sky) == 2
    assert "a sky camera's bundle" in capsys.readouterr().err
