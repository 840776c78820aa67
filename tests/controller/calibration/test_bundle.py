import numpy as np
import pytest

from controller.calibration import (
    AzimuthCal,
    CalibrationBundle,
    CameraCal,
    LevelCal,
    PoseCal,
    SurfaceCal,
    load_bundle,
    save_bundle,
)
from controller.errors import ConfigError

CAM = CameraCal(640, 480, 500.0, 501.0, 320.0, 240.0, (-0.1, 0.01, 0.0, 0.0, 0.0), rms_px=0.1)


def test_round_trip(tmp_path):
    b = CalibrationBundle(
        camera=CAM,
        surface=SurfaceCal("sphere", (0.0, 0.0, 0.001), 0.2, rmse_m=2e-4),
        pose=PoseCal(rvec=(0.1, 0.2, 0.3), tvec=(0.0, 0.0, 1.0)),
        level=LevelCal(zenith_model=(0.0, 0.01, 1.0)),
        azimuth=AzimuthCal(12.5),
    )
    p = save_bundle(b, tmp_path / "x" / "b.toml")
    r = load_bundle(p)
    assert r.camera == b.camera and r.surface == b.surface and r.pose == b.pose
    assert r.level == b.level and r.azimuth_offset_deg == 12.5


def test_relative_paths_resolve_against_the_bundle_folder(tmp_path, monkeypatch):
    d = tmp_path / "inst"
    d.mkdir()
    np.savez(d / "cloud.npz", points=np.random.default_rng(0).normal(size=(50, 3)))
    (d / "b.toml").write_text(
        "[camera]\nwidth = 640\nheight = 480\nfx = 500.0\nfy = 500.0\ncx = 320.0\ncy = 240.0\n"
        'dist = [0.0, 0.0, 0.0, 0.0, 0.0]\n[surface]\ncloud = "cloud.npz"\n'
    )
    monkeypatch.chdir(tmp_path)
    b = load_bundle(d / "b.toml")
    assert b.surface.cloud == d / "cloud.npz"


@pytest.mark.parametrize(
    "text,key",
    [
        ("[camera]\nwidth = 640\n", "camera.height"),
        (
            "[camera]\nwidth = 640\nheight = 480\nfx = 500.0\nfy = 500.0\ncx = 1\ncy = 1\ndist = [1, 2]\n",
            "camera.dist",
        ),
        ("[camera]\nwidth = 640\nheight = 480\nfx = -5.0\nfy = 500.0\ncx = 1\ncy = 1\n", "camera.fx"),
        (
            "[camera]\nwidth = 640\nheight = 480\nfx = 5.0\nfy = 500.0\ncx = 1\ncy = 1\n"
            '[surface]\nkind = "cone"\n',
            "surface.kind",
        ),
        (
            "[camera]\nwidth = 640\nheight = 480\nfx = 5.0\nfy = 500.0\ncx = 1\ncy = 1\n"
            "[pose]\nmarkers_model = [[0,0,0],[1,0,0],[0,1,0],[1,1,0]]\nmarkers_image = [[1,1]]\n",
            "pose.markers_image",
        ),
        (
            "[camera]\nwidth = 640\nheight = 480\nfx = 5.0\nfy = 500.0\ncx = 1\ncy = 1\n"
            '[surface]\ncloud = "nope.ply"\n',
            "surface.cloud",
        ),
        ("this is = not toml [", ""),
        (  # an audit's case: accepted before
            "[camera]\nwidth = 640\nheight = 480\nfx = 5.0\nfy = 500.0\ncx = 1\ncy = 1\n[azimuth]\noffset_deg = 1e308\n",
            "azimuth.offset_deg",
        ),
    ],
)
def test_errors_name_file_key_and_expectation(tmp_path, text, key):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    with pytest.raises(ConfigError) as ei:
        load_bundle(p)
    assert ei.value.file == str(p)
    assert ei.value.key == key
    assert "expected" in str(ei.value)


def test_missing_file_is_a_config_error(tmp_path):
    with pytest.raises(ConfigError):
        load_bundle(tmp_path / "none.toml")
