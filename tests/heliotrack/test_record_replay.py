"""`hil record` writes the frames the live simulation sees; `replay` feeds them back through
the whole controller and scores them against truth.csv (the acceptance figure, shortened:
the replay's pointing error equals the live run's within 0.05 deg RMS)."""

import json
from pathlib import Path

import cv2
import numpy as np
import pandas as pd
import pytest

from controller.timestamps import time_from_name
from heliotrack.cli import main
from heliotrack.replay import open_frames
from tests.conftest import REPO

HOTSPOT = REPO / "config" / "hil-hotspot.toml"
START = "2024-03-20T05:00:00Z"
HOURS = "1"


def scenario(folder: Path) -> Path:
    """The hotspot scenario with the paper's camera (its smaller globe image renders and
    calibrates faster), a frame and a setpoint every 10 minutes."""
    text = HOTSPOT.read_text().replace("period_s = 60.0", "period_s = 600.0")
    text = text.replace("enabled = true ", "enabled = false ")  # DIFFUSE needs 1-min samples
    text = text.replace(
        'calibration = "calibration/recommended.toml"', f'calibration = "{REPO}/config/calibration/seed.toml"'
    )
    text = text.replace('profile = "recommended"', 'profile = "seed"')
    p = folder / "hotspot.toml"
    p.write_text(text)
    return p


@pytest.fixture(scope="module")
def recorded(tmp_path_factory):
    """(config, frames folder, live summary, live cycles) of one hour, a frame per cycle."""
    tmp = tmp_path_factory.mktemp("record")
    cfg = scenario(tmp)
    frames = tmp / "frames"
    assert (
        main(
            ["hil", "record", "--config", str(cfg), "--start", START, "--hours", HOURS, "--out", str(frames)]
        )
        == 0
    )
    live = tmp / "live"
    args = [
        "simulate",
        "--config",
        str(cfg),
        "--start",
        START,
        "--hours",
        HOURS,
        "--out",
        str(live),
        "--no-report",
    ]
    assert main(args) == 0
    return cfg, frames, json.loads((live / "summary.json").read_text()), pd.read_csv(live / "cycles.csv")


def replay(tmp_path, cfg, source, *extra) -> dict:
    out = tmp_path / "replay"
    assert main(["replay", str(source), "--config", str(cfg), "--out", str(out), "--no-report", *extra]) == 0
    return json.loads((out / "summary.json").read_text())


def test_record_names_frames_by_utc_time_and_writes_the_truth(recorded):
    _, frames, _, _ = recorded
    names = sorted(p.name for p in frames.glob("*.png"))
    assert names[0] == "2024-03-20T05-00-00Z.png" and len(names) == 6
    truth = pd.read_csv(frames / "truth.csv")
    assert list(truth["frame"]) == names
    times = [time_from_name(n) for n in names]
    assert np.allclose(np.diff(times), 600.0)
    assert truth["sun_visible"].all() and truth["sun_el_deg"].between(20, 60).all()
    img = cv2.imread(str(frames / names[0]), cv2.IMREAD_UNCHANGED)
    assert img.shape == (1080, 960) and img.dtype == np.uint8


def test_replay_of_a_recorded_hour_points_like_the_live_run(recorded, tmp_path, capsys):
    cfg, frames, live, live_rows = recorded
    s = replay(tmp_path, cfg, frames)
    assert s["command"] == "replay" and s["replay"]["truth"].endswith("truth.csv")
    assert s["cycles"] == live["cycles"] and s["camera_frames"] == live["camera_frames"] == {"found": 6}
    assert s["sources"] == live["sources"]
    for name, t in live["trackers"].items():
        rms_live = t["pointing_error_deg"]["rms"]
        rms_replay = s["trackers"][name]["pointing_error_deg"]["rms"]
        if rms_live is not None:
            assert abs(rms_replay - rms_live) <= 0.05, name
    rows = pd.read_csv(tmp_path / "replay" / "cycles.csv")
    diff = rows["pointing_error_deg"] - live_rows["pointing_error_deg"]
    assert np.sqrt(np.nanmean(diff**2)) <= 0.05
    assert "warning" not in capsys.readouterr().err


def test_frames_short_of_the_run_warn_and_without_truth_it_scores_on_the_ephemeris(
    recorded, tmp_path, capsys
):
    cfg, frames, live, _ = recorded
    bare = tmp_path / "bare"  # the frames without their truth.csv
    bare.mkdir()
    for p in frames.glob("*.png"):
        (bare / p.name).symlink_to(p)
    s = replay(tmp_path, cfg, bare, "--start", "2024-03-20T04:00:00Z", "--hours", "2")
    err = capsys.readouterr().err
    assert "heliotrack: warning: the frames cover 2024-03-20 05:00:00 to 2024-03-20 05:50:00 UTC" in err
    assert s["warnings"] and s["replay"]["truth"] == "ephemeris"
    assert s["camera_frames"]["found"] == 6 and s["camera_frames"]["no frame"] == 6
    assert s["sources"]["ephemeris"] > 0  # the hour before the frames
    assert s["pointing_error_deg"]["n"] > live["pointing_error_deg"]["n"]


def test_video_frames_are_timed_from_start_and_rate(recorded, tmp_path):
    _, frames, _, _ = recorded
    video = tmp_path / "cam.avi"
    pngs = sorted(frames.glob("*.png"))[:3]
    writer = cv2.VideoWriter(str(video), cv2.VideoWriter_fourcc(*"MJPG"), 2.0, (960, 1080), isColor=False)
    for p in pngs:
        writer.write(cv2.imread(str(p), cv2.IMREAD_GRAYSCALE))
    writer.release()
    t0 = time_from_name(pngs[0].name)
    src = open_frames(video, start=t0, fps=None)  # the rate from the file: 2 fps
    assert np.allclose(src.times, t0 + np.array([0.0, 0.5, 1.0]))
    assert src.grab(t0 - 0.1) is None and src.grab(t0 + 200.0) is None
    for k in (0, 2):  # frame 1 is skipped over
        frame = src.grab(t0 + 0.5 * k + 0.01)
        want = cv2.imread(str(pngs[k]), cv2.IMREAD_GRAYSCALE).astype(float)
        assert frame is not None and frame.image.shape == (1080, 960) and frame.time == t0 + 0.5 * k
        assert np.abs(frame.image.astype(float) - want).mean() < 3.0  # the same picture, MJPEG-coded
    assert src.grab(t0 + 1.2) is None  # each exposure is observed once


def test_replay_refuses_what_it_cannot_read(recorded, tmp_path, capsys):
    cfg, _, _, _ = recorded
    empty = tmp_path / "empty"
    empty.mkdir()
    (tmp_path / "clip.avi").write_bytes(b"not a video")
    for source, extra, expect in (
        (tmp_path / "missing", [], "no such folder"),
        (empty, [], "no images"),
        (tmp_path / "clip.avi", [], "carries no time"),
        (tmp_path / "clip.avi", ["--start", START], "not a video"),
    ):
        args = ["replay", str(source), "--config", str(cfg), "--out", str(tmp_path / "o"), *extra]
        assert main(args) == 2
        err = capsys.readouterr().err.strip()
        assert expect in err and len(err.splitlines()) == 1, err
        assert not (tmp_path / "o").exists()  # refused before --out is made (it had been left empty)
    args = [
        "replay",
        str(empty),
        "--config",
        str(REPO / "config" / "hil-default.toml"),
        "--out",
        str(tmp_path / "o2"),
    ]
    assert main(args) == 2
    assert "control.sun_source" in capsys.readouterr().err
    assert not (tmp_path / "o2").exists()


def test_a_folder_frame_is_observed_once(recorded):
    _, frames, _, _ = recorded
    src = open_frames(frames)
    t0 = float(src.times[0])
    assert src.grab(t0 - 1.0) is None
    first = src.grab(t0)
    assert first is not None and first.time == t0
    assert src.grab(t0 + 60.0) is None  # still the newest frame, already observed
    assert src.grab(t0 + 600.0).time == t0 + 600.0


def _copy(frames: Path, folder: Path, truth=lambda text: text) -> Path:
    folder.mkdir()
    for p in sorted(frames.glob("*.png")):
        (folder / p.name).symlink_to(p)
    (folder / "truth.csv").write_text(truth((frames / "truth.csv").read_text()), encoding="utf-8")
    return folder


@pytest.mark.parametrize("bad", ["nan", "inf", "NaN"])
def test_a_truth_that_is_not_a_number_is_named(recorded, tmp_path, capsys, bad):
    """An audit's case: NaN rows were dropped from the score unseen (n 8 instead of 88)."""
    cfg, frames, _, _ = recorded

    def spoil(text: str) -> str:
        lines = text.splitlines()
        head = lines[0].split(",")
        row = lines[2].split(",")
        row[head.index("sun_el_deg")] = bad
        return "\n".join([*lines[:2], ",".join(row), *lines[3:]]) + "\n"

    src = _copy(frames, tmp_path / "src", spoil)
    assert main(["replay", str(src), "--config", str(cfg), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert f"truth.csv:3: sun_el_deg: expected a finite number, got '{bad}'" in err


def test_a_truth_from_a_spreadsheet_with_a_bom_is_read(recorded, tmp_path, capsys):
    cfg, frames, live, _ = recorded
    src = _copy(frames, tmp_path / "src", lambda text: "\ufeff" + text)
    s = replay(tmp_path, cfg, src)
    assert s["replay"]["truth"].endswith("truth.csv") and "warning" not in capsys.readouterr().err


def test_a_truth_far_from_the_ephemeris_is_warned_about(recorded, tmp_path, capsys):
    """Azimuth from south (a PV habit): the score had gone on against it without a word."""
    cfg, frames, _, _ = recorded
    lines = (frames / "truth.csv").read_text().splitlines()
    az = lines[0].split(",").index("sun_az_deg")

    def from_south(text: str) -> str:
        rows = [r.split(",") for r in text.splitlines()]
        for r in rows[1:]:
            r[az] = f"{float(r[az]) - 180.0:.6f}"
        return "\n".join(",".join(r) for r in rows) + "\n"

    replay(tmp_path, cfg, _copy(frames, tmp_path / "src", from_south))
    assert "deg from the ephemeris's at the site" in capsys.readouterr().err


def test_frames_that_cannot_be_read_are_named_after_the_run(recorded, tmp_path, capsys):
    cfg, frames, _, _ = recorded
    src = _copy(frames, tmp_path / "src")
    victims = sorted(src.glob("*.png"))[1:3]
    for p in victims:
        p.unlink()
        p.write_bytes(b"")  # a camera that died mid-write
    s = replay(tmp_path, cfg, src)
    err = capsys.readouterr().err
    said = f"2 frame(s) could not be read (empty, truncated or not an image): {victims[0].name}"
    assert said in err
    assert s["camera_frames"]["found"] == 4
    assert any(said in w for w in s["warnings"])  # printed only, before: summary.json had none


def _renamed(frames: Path, folder: Path, name) -> Path:
    """The frames (without truth.csv) under the names ``name(k, path)`` gives."""
    folder.mkdir()
    for k, p in enumerate(sorted(frames.glob("*.png"))):
        (folder / name(k, p)).symlink_to(p)
    return folder


def test_a_last_frame_off_the_control_grid_gets_its_cycle():
    """Frames at 09:00:00, 09:01:29 and 09:02:29 under a 60-s period: the run had stopped at
    the 09:02 cycle, and the last frame (for 09:03) was never used (an audit)."""
    from heliotrack.replay import plan

    class Frames:
        times = 1710925200.0 + np.array([0.0, 89.0, 149.0])
        cadence_s = 74.5
        names: list = []

    assert plan(Frames(), 60.0, None, None).span.n_cycles == 4
    Frames.times = 1710925200.0 + np.array([0.0, 60.0, 120.0])  # on the grid: a cycle each
    assert plan(Frames(), 60.0, None, None).span.n_cycles == 3


def test_frame_names_without_a_zone_are_warned_about(recorded, tmp_path, capsys):
    cfg, frames, _, _ = recorded
    s = replay(
        tmp_path, cfg, _renamed(frames, tmp_path / "src", lambda k, p: p.name.replace("Z.png", ".png"))
    )
    assert (
        "6 of 6 frame names carry no zone (2024-03-20T05-00-00.png, ...): read as UTC"
        in capsys.readouterr().err
    )
    assert any("carry no zone" in w for w in s["warnings"])


def test_frames_denser_than_the_control_period_are_warned_about(recorded, tmp_path, capsys):
    """Frames every 10 s under a 600-s period: one is used a cycle, and the run had said nothing."""
    cfg, frames, _, _ = recorded
    s = replay(
        tmp_path, cfg, _renamed(frames, tmp_path / "src", lambda k, p: f"2024-03-20T05-00-{10 * k:02d}Z.png")
    )
    assert (
        "6 frames, one every 10 s, for 2 cycles of 600 s: at most 2 of them are used"
        in capsys.readouterr().err
    )
    assert s["cycles"] == 2


def test_a_replay_over_a_year_is_refused(recorded, tmp_path, capsys):
    """A wrong --start had planned 12 million cycles (30 hours), with a warning only."""
    cfg, frames, _, _ = recorded
    argv = [
        "replay",
        str(frames),
        "--config",
        str(cfg),
        "--start",
        "2000-01-01T00:00:00Z",
        "--out",
        str(tmp_path / "o"),
    ]
    assert main(argv) == 2
    assert "over 366 days" in capsys.readouterr().err


def test_a_recording_of_more_frames_than_a_year_at_a_minute_is_refused(tmp_path, capsys):
    """An audit's case: 3e9 frame times asked for 23.6 GiB before the first frame."""
    argv = ["hil", "record", "--hours", "8784", "--every", "0.01", "--out", str(tmp_path / "o")]
    assert main(argv) == 2
    assert "--every: expected at most 1,000,000 frames" in capsys.readouterr().err
    assert not (tmp_path / "o").exists()
