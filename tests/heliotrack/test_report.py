"""The run report: figures and one self-contained index.html, written by simulate and
rebuilt by `heliotrack report DIR`."""

import base64
import json
import re
from datetime import UTC, datetime

import cv2
import numpy as np
import pandas as pd
import pytest

from heliotrack.cli import main
from heliotrack.reports import figures
from heliotrack.reports.run_report import load_run
from hil.sky import sky_series
from tests.conftest import DEFAULT_CONFIG

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"


def images(page: str) -> dict[str, np.ndarray]:
    """Every <img> of the page, decoded; fails on anything but an embedded PNG."""
    out = {}
    for alt, src in re.findall(r'<img alt="([^"]+)" src="([^"]+)"', page):
        assert src.startswith("data:image/png;base64,"), src[:40]
        data = base64.b64decode(src.split(",", 1)[1], validate=True)
        assert data.startswith(PNG_MAGIC)
        img = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        assert img is not None and img.shape[0] > 100 and img.shape[1] > 100
        out[alt] = img
    assert page.count("<img") == len(out)
    return out


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    out = tmp_path_factory.mktemp("sim") / "out"
    args = ["simulate", "--config", str(DEFAULT_CONFIG), "--start", "2024-03-20T05:00:00+00:00"]
    assert main([*args, "--hours", "0.5", "--out", str(out)]) == 0
    return out


def test_simulate_writes_a_self_contained_report(run_dir):
    page = (run_dir / "report" / "index.html").read_text()
    figs = images(page)
    assert {"sky_dome", "pointing_error", "timeline", "setpoints"} <= set(figs)
    # nothing to fetch: no external script, style sheet, font or image
    assert not re.search(r"<script|<link|@import|url\(|src=\"(?!data:)", page)
    assert "dual-1" in page and "row-1" in page and "rms deg" in page
    for name in figs:
        assert (run_dir / "report" / f"{name}.png").read_bytes().startswith(PNG_MAGIC)


def test_a_short_run_is_said_in_hours(run_dir):
    """The page had said "1 day(s)" of a half-hour run, where the terminal said hours."""
    assert "0.5 hour(s) from 2024-03-20T05:00:00" in (run_dir / "report" / "index.html").read_text()


def test_a_report_that_cannot_be_written_is_one_line(run_dir, tmp_path, capsys):
    """A read-only or full report folder had given a traceback (the tests run as root,
    so a folder where a figure should go stands for it)."""
    out = tmp_path / "report"
    (out / "sky_dome.png").mkdir(parents=True)
    assert main(["report", str(run_dir), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "cannot write the report" in err and len(err.splitlines()) == 1, err


def test_report_rebuilds_from_the_run_outputs(run_dir, tmp_path, capsys):
    out = tmp_path / "again"
    assert main(["report", str(run_dir), "--out", str(out)]) == 0
    assert str(out / "index.html") in capsys.readouterr().out
    before = images((run_dir / "report" / "index.html").read_text())
    assert set(images((out / "index.html").read_text())) == set(before)


def test_ctrl_c_swallowed_by_a_gc_callback_still_stops_the_report(run_dir, tmp_path, monkeypatch):
    """A SIGINT that lands in a garbage collector's callback is printed as "Exception
    ignored" and Python runs on: Ctrl-C during a report had now and then been lost, and the
    report written to its end."""
    import gc
    import os
    import signal

    fired = []

    def ctrl_c_during_gc(phase, info):
        if phase == "start" and not fired:
            fired.append(True)
            os.kill(os.getpid(), signal.SIGINT)  # handled here, inside the callback: swallowed

    drawn = figures.pointing_error

    def pointing_error_then_gc(df):
        fig = drawn(df)
        gc.callbacks.append(ctrl_c_during_gc)
        try:
            gc.collect()  # a collection while the report draws, as matplotlib's garbage brings
        finally:
            gc.callbacks.remove(ctrl_c_during_gc)
        return fig

    monkeypatch.setattr(figures, "pointing_error", pointing_error_then_gc)
    out = tmp_path / "stopped"
    assert main(["report", str(run_dir), "--out", str(out)]) == 130
    assert fired and not (out / "index.html").exists()
    assert signal.getsignal(signal.SIGINT) is signal.default_int_handler
    monkeypatch.undo()
    assert main(["report", str(run_dir), "--out", str(out)]) == 0


def test_report_of_a_folder_without_a_run_is_one_line(tmp_path, capsys):
    assert main(["report", str(tmp_path)]) == 2
    err = capsys.readouterr().err.strip()
    assert "summary.json: not found" in err and len(err.splitlines()) == 1


def synthetic_run(folder, days=("clear", "overcast")):
    """A two-day run folder: one dual-axis tracker, pyranometer readings of a clear then an
    overcast day, what the sun-path filter learned each day, a wind alarm."""
    lat, lon = 32.4835, 48.3364
    t0 = datetime(2024, 3, 20, tzinfo=UTC).timestamp() - lon / 15 * 3600
    t = t0 + np.arange(len(days) * 1440) * 60.0
    sky = sky_series(t, lat, lon, 150.0, dict(enumerate(days)))
    alarms = np.where((t > t0 + 36 * 3600) & (t < t0 + 37 * 3600), "wind 21.0 m/s >= 20.0", "")
    rows = pd.DataFrame(
        {
            "time_utc": [datetime.fromtimestamp(x, UTC).isoformat() for x in t],
            "tracker": "dual-1",
            "mode": np.where(alarms != "", "STOW", "TRACK"),
            "reason": np.where(alarms != "", "wind stow", "sun up"),
            "source": "ephemeris",
            "sun_az_deg": 180.0,
            "sun_el_deg": 40.0,
            "ghi_w_m2": sky.ghi,
            "alarms": alarms,
            "health": "ok",
        }
    )
    folder.mkdir(parents=True)
    rows.to_csv(folder / "cycles.csv", index=False)
    summary = {
        "command": "simulate",
        "days": len(days),
        "start": "2024-03-20",
        "sky": list(days),
        "site": {"latitude": lat, "longitude": lon, "altitude": 150.0},
        "control_period_s": 60.0,
        "cycles": len(t),
        "trackers": {"dual-1": {"pointing_error_deg": {"mean": 0.1}}},
        "sun_path_days": [
            {"day": "2024-03-20", "lat_error_deg": 0.01, "lon_error_deg": -0.02, "noon_error_s": 4.8},
            {"day": "2024-03-21", "lat_error_deg": 0.005, "lon_error_deg": -0.01, "noon_error_s": 2.4},
        ],
        "weather": {"storms": 1, "alarms": 1},
    }
    (folder / "summary.json").write_text(json.dumps(summary))
    return folder


def test_multi_day_figures_and_weather_on_the_timeline(tmp_path):
    run = synthetic_run(tmp_path / "run")
    assert main(["report", str(run)]) == 0
    figs = images((run / "report" / "index.html").read_text())
    assert {"daily_sun_path", "sky_classes", "timeline"} <= set(figs)
    df, summary = load_run(run)
    lanes = [lab.get_text() for lab in figures.timeline(df, 60.0).axes[0].get_yticklabels()]
    assert "alarms" in lanes and "dual-1 mode" in lanes
    bars = figures.sky_classes(df, summary).axes[0].patches
    assert [round(b.get_height()) for b in bars] == [1, 3]  # class I clear, class III overcast


def test_a_run_that_wrote_fewer_columns_still_gets_its_report(tmp_path):
    # e.g. `heliotrack run` on a real plant: no truth, no pointing error, no setpoints
    (tmp_path / "cycles.csv").write_text(
        "time_utc,tracker,mode,source,sun_az_deg,sun_el_deg\n"
        "2024-03-20T06:00:00+00:00,a,TRACK,ephemeris,100.0,20.0\n"
        "2024-03-20T06:01:00+00:00,a,TRACK,observed,100.2,not a number\n"
    )
    (tmp_path / "summary.json").write_text(
        json.dumps({"command": "run", "site": {"latitude": 32, "longitude": 48}})
    )
    assert main(["report", str(tmp_path)]) == 0
    figs = images((tmp_path / "report" / "index.html").read_text())
    assert set(figs) == {"sky_dome", "timeline"}  # the true sun from the ephemeris


@pytest.mark.parametrize(
    ("edit", "needle"),
    [
        (
            lambda f: (f / "cycles.csv").write_text((f / "cycles.csv").read_text().splitlines()[0] + "\n"),
            "no cycle with a readable time_utc",
        ),
        (
            lambda f: (f / "summary.json").write_text('{"trackers": {"dual-1": 5}}'),
            "not the outputs of a heliotrack run (AttributeError",
        ),
        (
            lambda f: (f / "summary.json").write_text('{"control_period_s": "abc"}'),
            "not the outputs of a heliotrack run (ValueError",
        ),
        (lambda f: (f / "report").write_text("x"), "cannot make the report folder"),
    ],
)
def test_a_run_folder_that_is_no_run_is_one_line_and_the_old_report_stays(tmp_path, capsys, edit, needle):
    """An audit's cases: each had ended in a traceback."""
    folder = synthetic_run(tmp_path / "run", days=("clear",))
    assert main(["report", str(folder), "--out", str(tmp_path / "kept")]) == 0
    before = (tmp_path / "kept" / "index.html").read_text()
    edit(folder)
    capsys.readouterr()
    assert main(["report", str(folder)]) == 2
    err = capsys.readouterr().err.strip()
    assert needle in err and len(err.splitlines()) == 1 and "Traceback" not in err
    if not (folder / "report").is_file():
        assert main(["report", str(folder), "--out", str(tmp_path / "kept")]) == 2
        assert (tmp_path / "kept" / "index.html").read_text() == before
