"""Bad input to the hotspot's calibration steps, ``sunpath`` and ``classify``: one line and
exit 2, before any work (no hang, no traceback), and a bundle that a failed step leaves as
it was.  Each case is one an audit of the command line found (2026-12-01)."""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest

from heliotrack.cli import main

REPO = Path(__file__).resolve().parents[2]
BUNDLE = REPO / "config" / "calibration" / "recommended.toml"


@pytest.fixture
def bundle(tmp_path) -> Path:
    b = tmp_path / "b.toml"
    shutil.copy(BUNDLE, b)
    return b


def error_of(capsys, argv) -> str:
    """The one-line error of ``argv`` (exit 2 from the command or from argparse)."""
    try:
        rc = main(argv)
    except SystemExit as exc:
        rc = exc.code
    assert rc == 2, argv
    return capsys.readouterr().err.strip().splitlines()[-1]


def sphere_points(n: int = 200) -> np.ndarray:
    rng = np.random.default_rng(0)
    v = rng.normal(size=(n, 3))
    return 0.2 * v / np.linalg.norm(v, axis=1, keepdims=True)


@pytest.mark.parametrize(
    "edit, message",
    [
        (lambda p: np.vstack([p, [np.inf, 0, 0]]), "point 201: not finite"),  # hung in LAPACK
        (lambda p: np.vstack([p, [np.nan, 0, 0]]), "point 201: not finite"),
        (lambda p: p * [1, 1, 0], "lie on a plane or a line"),
    ],
)
def test_a_cloud_that_is_no_surface_is_refused_and_the_bundle_kept(tmp_path, capsys, bundle, edit, message):
    cloud = tmp_path / "scan.xyz"
    np.savetxt(cloud, edit(sphere_points()))
    before = bundle.read_text()
    err = error_of(
        capsys, ["calibrate", "surface", "--cloud", str(cloud), "--fit-sphere", "--bundle", str(bundle)]
    )
    assert message in err and bundle.read_text() == before


def test_the_surface_step_stores_the_fitted_sphere_unless_told_to_keep_the_scan(tmp_path, capsys, bundle):
    import tomllib

    cloud = tmp_path / "scan.xyz"
    np.savetxt(cloud, sphere_points() + [0.01, -0.02, 0.03])
    assert main(["calibrate", "surface", "--cloud", str(cloud), "--bundle", str(bundle)]) == 0
    srf = tomllib.loads(bundle.read_text())["surface"]
    assert srf["kind"] == "sphere" and srf["radius"] == pytest.approx(0.2, abs=1e-9)
    assert srf["center"] == pytest.approx([0.01, -0.02, 0.03], abs=1e-9)
    assert main(["calibrate", "surface", "--cloud", str(cloud), "--keep-cloud", "--bundle", str(bundle)]) == 0
    assert "not reliable" in capsys.readouterr().out
    assert tomllib.loads(bundle.read_text())["surface"]["kind"] == "cloud"
    argv = [
        "calibrate",
        "surface",
        "--cloud",
        str(cloud),
        "--keep-cloud",
        "--fit-sphere",
        "--bundle",
        str(bundle),
    ]
    assert "exclude each other" in error_of(capsys, argv)


def test_a_pose_that_comes_out_nan_or_far_off_is_not_written(tmp_path, capsys, bundle):
    picked = tmp_path / "picked.csv"
    rows = [[0.1 * i, 0.05 * (i % 2), 0.0, 100.0 + 10 * i, np.nan] for i in range(6)]
    np.savetxt(picked, rows, delimiter=",", header="x,y,z,u,v", comments="")
    before = bundle.read_text()
    err = error_of(capsys, ["calibrate", "pose", "--picked", str(picked), "--bundle", str(bundle)])
    assert "pose: the markers reproject nan px RMS" in err
    assert bundle.read_text() == before


def test_plumb_lines_with_a_nan_are_refused(tmp_path, capsys, bundle):
    lines = tmp_path / "lines.csv"
    lines.write_text("line,u,v\n0,10,20\n0,nan,40\n1,50,60\n1,55,90\n")
    err = error_of(capsys, ["calibrate", "level", "--lines", str(lines), "--bundle", str(bundle)])
    assert f"{lines}: row 3: not finite" in err


@pytest.mark.parametrize(
    "content, message",
    [
        (None, "expected JSON lines from heliotrack estimate"),  # no such file
        ("[1, 2, 3]\n", ":1: expected a JSON object"),
        ('{"found": true, "levelled_az_deg": NaN, "levelled_el_deg": 40}\n', ":1: levelled_az_deg"),
    ],
)
def test_azimuth_observations_that_are_not_estimates_are_named(tmp_path, capsys, bundle, content, message):
    obs = tmp_path / "obs.jsonl"
    if content is not None:
        obs.write_text(content)
    err = error_of(capsys, ["calibrate", "azimuth", "--observations", str(obs), "--bundle", str(bundle)])
    assert message in err


@pytest.mark.parametrize(
    "argv, message",
    [
        (
            [
                "calibrate",
                "azimuth",
                "--observations",
                "o.jsonl",
                "--lat=nan",
                "--lon=48",
                "--bundle",
                "b.toml",
            ],
            "argument --lat: expected a number in [-90, 90]",
        ),
        (["calibrate", "all", "folder", "--lat=95", "--lon=48", "--bundle", "b.toml"], "argument --lat"),
        (
            ["calibrate", "all", "folder", "--shape-degree=50", "--bundle", "b.toml"],
            "argument --shape-degree",
        ),
        (
            ["calibrate", "intrinsics", "--pattern=1x1", "--square=0.04", "--bundle", "b.toml", "x.png"],
            "argument --pattern: expected inner corners like 9x6",
        ),
        (["calibrate", "intrinsics", "--square=0", "--bundle", "b.toml", "x.png"], "argument --square"),
        (["sunpath", "obs.csv", "--utc-offset=nan"], "argument --utc-offset"),
        (["classify", "x.csv", "--lat=32", "--lon=48", "--alt=nan"], "argument --alt"),
        (
            [
                "sunpath",
                "predict",
                "--lat=32",
                "--lon=48",
                "--start=2026-01-01T00:00Z",
                "--end=2036-01-01T00:00Z",
                "--step-min=0.0001",
            ],
            "steps from --start to --end",
        ),
    ],
)
def test_impossible_numbers_are_refused_before_any_work(capsys, argv, message):
    assert message in error_of(capsys, argv)


def test_a_bundle_with_an_impossible_pose_is_named(tmp_path, capsys, bundle):
    text = bundle.read_text().replace("rvec = [2.355593610548941", "rvec = [1e300", 1)
    bundle.write_text(text)
    frame = tmp_path / "f.png"
    frame.write_bytes(b"")
    err = error_of(capsys, ["estimate", "--calib", str(bundle), str(frame)])
    assert "pose.rvec: expected a rotation vector of at most 4 pi rad" in err


def test_a_pose_far_from_its_markers_is_refused(tmp_path, capsys, bundle):
    picked = tmp_path / "picked.csv"
    rng = np.random.default_rng(1)
    rows = np.column_stack([rng.uniform(-0.1, 0.1, (8, 2)), np.zeros(8), rng.uniform(0, 900, (8, 2))])
    np.savetxt(picked, rows, delimiter=",", header="x,y,z,u,v", comments="")
    before = bundle.read_text()
    err = error_of(capsys, ["calibrate", "pose", "--picked", str(picked), "--bundle", str(bundle)])
    assert "px RMS from where they were seen (at most 10)" in err and bundle.read_text() == before


def test_a_cut_above_the_sphere_is_refused(tmp_path, capsys, bundle):
    cloud = tmp_path / "scan.xyz"
    np.savetxt(cloud, sphere_points())
    argv = [
        "calibrate",
        "surface",
        "--cloud",
        str(cloud),
        "--fit-sphere",
        "--min-z",
        "0.5",
        "--bundle",
        str(bundle),
    ]
    assert "is above the fitted sphere's top" in error_of(capsys, argv)


def test_plumb_lines_that_are_not_vertical_are_refused_and_the_bundle_kept(tmp_path, capsys, bundle):
    lines = tmp_path / "lines.csv"  # two horizontal lines (an audit's case: a 63 deg tilt)
    lines.write_text("line,u,v\n0,0,100\n0,900,100\n1,0,300\n1,900,300\n")
    before = bundle.read_text()
    err = error_of(capsys, ["calibrate", "level", "--lines", str(lines), "--bundle", str(bundle)])
    assert "level.zenith_model: expected a zenith within 45 deg of the model's z axis" in err
    assert bundle.read_text() == before


def test_the_noon_method_needs_both_sides_of_noon():
    from controller.calibration.azimuth import noon_offset
    from controller.errors import InputError

    az = np.linspace(100.0, 170.0, 10)  # a morning: the apex would be extrapolated
    el = 60.0 - 0.01 * (az - 203.0) ** 2
    with pytest.raises(InputError, match="10 before and 0 after"):
        noon_offset(az, el)
    az = np.linspace(120.0, 240.0, 13)
    assert noon_offset(az, 60.0 - 0.01 * (az - 203.0) ** 2) == pytest.approx(23.0)


@pytest.mark.parametrize(
    "tvec, message",
    [
        ("[0.0, 0.04, -0.8]", "pose: expected a camera that sees the surface"),  # the globe behind it
        (
            "[0.17, 41.0, 799.7]",
            "pose.tvec: expected a camera within 20 m of the surface's model origin",
        ),  # mm
        (  # a fuzzed file's: its length overflowed numpy's norm (a RuntimeWarning) on the way
            "[1e200, 0.0, 1e200]",
            "pose.tvec: expected a camera within 20 m of the surface's model origin",
        ),
    ],
)
@pytest.mark.filterwarnings("error")
def test_a_bundle_whose_camera_cannot_see_the_surface_is_named_at_load(
    tmp_path, capsys, bundle, tvec, message
):
    text = bundle.read_text()
    start = text.index("tvec = [")
    end = text.index("]", start) + 1
    bundle.write_text(text[:start] + f"tvec = {tvec}" + text[end:])
    frame = tmp_path / "f.png"
    frame.write_bytes(b"")
    assert message in error_of(capsys, ["estimate", "--calib", str(bundle), str(frame)])


def day_of_observations(path, lat, lon, start, hours, step_s=1800.0, min_el=5.0):
    """``heliotrack estimate``'s lines for a day of the sun at a site, levelled 23 deg off."""
    import json as _json

    from controller.sun.source import Site, solar_position
    from controller.timestamps import to_iso

    ts = [start + step_s * k for k in range(int(hours * 3600 / step_s))]
    sp = solar_position(Site(lat, lon), ts)
    path.write_text(
        "".join(
            _json.dumps(
                {"found": True, "time": to_iso(t), "levelled_az_deg": (a + 23.0) % 360, "levelled_el_deg": e}
            )
            + "\n"
            for t, a, e in zip(ts, sp["azimuth"], sp["apparent_elevation"])
            if e > min_el
        )
    )
    return path


@pytest.mark.parametrize(
    "lat, lon, start, culminates",
    [
        (-33.9, 18.4, 1750481160.0, "north"),  # Cape Town, 21 Jun 2025: the paper's south was 180 deg off
        (10.0, 77.0, 1750467120.0, "north"),  # 10 N in June: north of the zenith
        (32.4835, 48.3364, 1742439000.0, "south"),  # 20 Mar 2025; each from 6 h before noon
    ],
)
def test_the_noon_method_finds_where_the_sun_culminates_from_its_motion(
    tmp_path, capsys, bundle, lat, lon, start, culminates
):
    import json as _json

    obs = day_of_observations(tmp_path / "obs.jsonl", lat, lon, start, 12.0)
    capsys.readouterr()
    assert main(["calibrate", "azimuth", "--observations", str(obs), "--bundle", str(bundle)]) == 0
    out = _json.loads(capsys.readouterr().out)
    assert out["culminates"] == culminates and out["culminates_from"] == "the sun's motion"
    assert out["offset_deg"] == pytest.approx(23.0, abs=0.5)  # the parabola's own error, not 180 deg
    before = bundle.read_text()
    other = "south" if culminates == "north" else "north"
    argv = ["calibrate", "azimuth", "--observations", str(obs), "--culminates", other]
    err = error_of(capsys, [*argv, "--bundle", str(bundle)])
    assert f"--culminates {other}: the observations' sun culminates in the {culminates}" in err
    assert bundle.read_text() == before


def test_the_noon_method_refuses_a_midnight_sun_day(tmp_path, capsys, bundle):
    obs = day_of_observations(tmp_path / "obs.jsonl", 69.6, 18.9, 1750464000.0, 24.0, min_el=3.0)  # 21 Jun
    before = bundle.read_text()
    err = error_of(capsys, ["calibrate", "azimuth", "--observations", str(obs), "--bundle", str(bundle)])
    assert "round the horizon (a midnight-sun day)" in err and bundle.read_text() == before


@pytest.mark.parametrize("lon, ok", [("48.3364", True), ("-131.6636", False), ("-48.3364", False)])
def test_the_ephemeris_method_refuses_a_site_that_does_not_fit_the_day(tmp_path, capsys, bundle, lon, ok):
    import json as _json

    # 20 Mar 2025, 06:00-13:30 UTC
    obs = day_of_observations(tmp_path / "obs.jsonl", 32.4835, 48.3364, 1742450400.0, 8.0)
    argv = [
        "calibrate",
        "azimuth",
        "--observations",
        str(obs),
        "--method",
        "ephemeris",
        "--lat=32.4835",
        f"--lon={lon}",
    ]
    if ok:
        assert main([*argv, "--bundle", str(bundle)]) == 0
        assert _json.loads(capsys.readouterr().out)["offset_deg"] == pytest.approx(23.0, abs=0.01)
    else:
        before = bundle.read_text()
        err = error_of(capsys, [*argv, "--bundle", str(bundle)])
        assert "check --lat/--lon and the times" in err and bundle.read_text() == before


@pytest.mark.parametrize("make, what", [(None, "not found"), ("file", "not a folder")])
def test_calibrate_all_names_a_folder_that_is_not_one(tmp_path, capsys, make, what):
    folder = tmp_path / "install"
    if make == "file":
        folder.write_text("")
    err = error_of(capsys, ["calibrate", "all", str(folder), "--bundle", str(tmp_path / "b.toml")])
    assert f"{folder}: {what}: expected an installer's folder" in err
