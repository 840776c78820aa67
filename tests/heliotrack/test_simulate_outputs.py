"""What `simulate` writes and refuses: a tidy cycles.csv written as the run goes, a partial
summary on Ctrl-C, bounded memory and days, an unwritable --out or a real port refused
before the run."""

import fcntl
import json
import os
import signal
import struct
import subprocess
import sys
import termios
import time
import tracemalloc

import numpy as np
import pandas as pd
import pytest

from heliotrack.cli import main
from heliotrack.scenario import load_scenario
from heliotrack.scoring import ErrorStats
from heliotrack.simulate import ScenarioRun, simulation_span
from tests.conftest import DEFAULT_CONFIG

MORNING = "2024-03-20T05:00:00+00:00"


def short_config(tmp_path, period=600.0):
    text = DEFAULT_CONFIG.read_text().replace("period_s = 60.0", f"period_s = {period}")
    if period > 60:
        text = text.replace("enabled = true ", "enabled = false ")  # DIFFUSE needs 1-min samples
    p = tmp_path / "scenario.toml"
    p.write_text(text)
    return p


def test_cycles_csv_is_tidy_one_column_per_axis(tmp_path, capsys):
    out = tmp_path / "out"
    args = ["simulate", "--config", str(short_config(tmp_path, 60.0)), "--start", MORNING, "--hours", "0.5"]
    assert main([*args, "--out", str(out), "--no-report"]) == 0
    df = pd.read_csv(out / "cycles.csv")
    assert len(df) == 30 * 2
    for col in ("target_az_deg", "target_el_deg", "target_rot_deg", "actual_az_deg", "actual_el_deg"):
        assert col in df and df[col].dtype == float, col
    dual, row = df[df.tracker == "dual-1"], df[df.tracker == "row-1"]
    assert dual["target_rot_deg"].isna().all() and row["target_az_deg"].isna().all()
    assert dual["target_el_deg"].notna().all() and row["actual_rot_deg"].notna().all()
    # the drive's status word as flag names, its axis modes, its health
    assert df["status"].str.contains("HOMED").all()
    assert set(dual["drive_mode_az"]) <= {"AUTO", "STOW"}
    assert set(df["health"]) == {"ok"}
    # the true sun and the pyranometer's reading beside the controller's estimate
    assert (df["true_sun_el_deg"] - df["sun_el_deg"]).abs().max() < 1.0
    assert df["ghi_w_m2"].notna().all()
    text = capsys.readouterr().out
    assert "mean deg" in text and "p95 deg" in text and "POA kWh/m2" in text


def test_ctrl_c_leaves_the_rows_and_a_partial_summary(tmp_path):
    out = tmp_path / "out"
    cmd = [sys.executable, "-m", "heliotrack.cli", "simulate", "--config", str(short_config(tmp_path, 60.0))]
    proc = subprocess.Popen(
        [*cmd, "--days", "2", "--out", str(out)],  # stderr is a pipe: no progress bar
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        deadline = time.monotonic() + 240
        while time.monotonic() < deadline and proc.poll() is None:
            csv_file = out / "cycles.csv"
            if csv_file.exists() and len(csv_file.read_text().splitlines()) > 40:
                break  # rows are on disk while the run goes on
            time.sleep(0.2)
        assert proc.poll() is None, proc.communicate()
        proc.send_signal(signal.SIGINT)
        stdout, stderr = proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, stderr
    assert "Traceback" not in stderr and "cycle/s" not in stderr and "%|" not in stderr
    s = json.loads((out / "summary.json").read_text())
    assert s["interrupted"] is True and 20 <= s["cycles"] < 2 * 1440
    rows = pd.read_csv(out / "cycles.csv")
    assert len(rows) == 2 * s["cycles"]  # every finished cycle's rows, nothing half-written
    assert "INTERRUPTED" in stdout and (out / "report" / "index.html").exists()


def test_a_long_run_does_not_allocate_its_truth_up_front():
    # --days 100000 tried to allocate 4.3 GiB of truth before the first cycle; the truth is
    # now computed one day at a time, so even the longest run starts small.
    config = load_scenario(DEFAULT_CONFIG)
    tracemalloc.start()
    try:
        ScenarioRun(config, simulation_span(config, days=3660), progress=False)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert peak < 20e6


def test_days_beyond_the_bound_are_refused_in_one_line(tmp_path, capsys):
    assert main(["simulate", "--days", "100000", "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert "--days" in err and "3660" in err and len(err.splitlines()) == 1


def test_an_unwritable_out_fails_before_the_run(tmp_path, capsys):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    assert main(["simulate", "--days", "1", "--out", str(blocker / "sub")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith("heliotrack: error: --out:") and len(err.splitlines()) == 1


@pytest.mark.parametrize(
    ("name", "make"), [("cycles.csv", "mkdir"), ("summary.json", "mkdir"), ("report", "file")]
)
def test_an_out_whose_files_are_folders_or_report_a_file_fails_before_the_run(tmp_path, capsys, name, make):
    out = tmp_path / "o"
    out.mkdir()
    (out / name).mkdir() if make == "mkdir" else (out / name).write_text("x")
    assert main(["simulate", "--days", "1", "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.startswith(f"heliotrack: error: --out: {out / name} is a") and len(err.splitlines()) == 1


def test_a_run_stopped_before_its_first_cycle_leaves_the_earlier_run(tmp_path, capsys):
    """Ctrl-C during the start-up had truncated cycles.csv to its header, written a summary
    of 0 cycles, and crashed building the report (an audit of replay)."""
    from heliotrack.commands.simulate import finish
    from heliotrack.output import CyclesWriter

    config = load_scenario(DEFAULT_CONFIG)
    out = tmp_path / "o"
    out.mkdir()
    (out / "cycles.csv").write_text("the earlier run\n")
    with CyclesWriter(out / "cycles.csv", config.trackers) as w:
        w.write([])
    assert (out / "cycles.csv").read_text() == "the earlier run\n"
    assert finish({"cycles": 0, "interrupted": True}, out) == 130
    assert "interrupted before the first" in capsys.readouterr().err
    assert sorted(p.name for p in out.iterdir()) == ["cycles.csv"]
    with CyclesWriter(out / "cycles.csv", config.trackers) as w:  # the first rows replace it
        w.write([{"tracker": "dual-1"}])
    lines = (out / "cycles.csv").read_text().splitlines()
    assert lines[0].startswith("time_utc,") and "dual-1" in lines[1]


@pytest.mark.parametrize(
    ("argv", "needle"),
    [
        (["simulate", "--start", "2924-03-20"], "--start: expected a date in the years 1900-2200"),
        (["simulate", "--start", "9999-12-31T23:00:00Z"], "--start: year 9999 is outside 1900-2200"),
        (
            ["hil", "record", "--start", "2924-03-20", "--hours", "0.05"],
            "--start: expected a date in the years",
        ),
        (["replay", "samples/frames", "--start", "1677-01-01T00:00:00Z"], "--start: year 1677 is outside"),
    ],
)
def test_a_start_centuries_away_is_one_line(tmp_path, capsys, argv, needle):
    """An audit's cases: they had ended in pandas' OutOfBoundsDatetime (exit 1)."""
    from pathlib import Path

    argv = [str(Path(__file__).parents[2] / a) if a == "samples/frames" else a for a in argv]
    assert main([*argv, "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert needle in err and len(err.splitlines()) == 1
    assert not (tmp_path / "o" / "truth.csv").exists()


def test_a_real_port_is_refused_with_a_pointer_to_run(tmp_path, capsys):
    cfg = tmp_path / "plant.toml"
    cfg.write_text(DEFAULT_CONFIG.read_text().replace('port = "hil"', 'port = "/dev/ttyUSB0"'))
    assert main(["simulate", "--config", str(cfg), "--out", str(tmp_path / "o")]) == 2
    err = capsys.readouterr().err.strip()
    assert "links[0].port" in err and "heliotrack run" in err and "/dev/ttyUSB0" in err
    assert not (tmp_path / "o").exists()


def test_running_error_statistics_match_the_whole_sample():
    rng = np.random.default_rng(3)
    parts = [np.abs(rng.normal(0, 0.1, n)) for n in (1000, 1, 5000)]
    a, b = ErrorStats(), ErrorStats()
    a.add(parts[0])
    a.add(parts[1])
    b.add(parts[2])
    whole = np.concatenate(parts)
    s = a.merged(b).summary()
    assert s["n"] == whole.size
    assert s["mean"] == pytest.approx(whole.mean(), abs=1e-5)
    assert s["rms"] == pytest.approx(np.sqrt(np.mean(whole**2)), abs=1e-5)
    assert s["p95"] == pytest.approx(np.percentile(whole, 95), abs=2e-5)
    assert s["max"] == pytest.approx(whole.max(), abs=1e-5)


def test_a_progress_bar_when_stderr_is_a_terminal(tmp_path):
    master, slave = os.openpty()
    fcntl.ioctl(slave, termios.TIOCSWINSZ, struct.pack("HHHH", 24, 100, 0, 0))  # a terminal's width
    try:
        cmd = [sys.executable, "-m", "heliotrack.cli", "simulate", "--config", str(short_config(tmp_path))]
        proc = subprocess.run(
            [*cmd, "--start", MORNING, "--hours", "1", "--out", str(tmp_path / "o"), "--no-report"],
            stdout=subprocess.DEVNULL,
            stderr=slave,
            timeout=300,
        )
        os.close(slave)
        seen = b""
        while True:
            try:
                chunk = os.read(master, 65536)
            except OSError:  # the pty's other end is closed: all read
                break
            if not chunk:
                break
            seen += chunk
    finally:
        os.close(master)
    assert proc.returncode == 0
    assert b"simulate:" in seen and b"cycle" in seen


def test_the_sensors_read_the_truth_up_to_the_worlds_closing(tmp_path):
    """The emulated pyranometer reads the day's truth from its server thread, also while a
    run ends (an interrupt left it reading nothing: an assertion inside pymodbus's request
    handler, logged with a traceback)."""
    cfg = load_scenario(short_config(tmp_path))
    run = ScenarioRun(cfg, simulation_span(cfg))
    run._enter_day(0)
    t = run.t0 + 12 * 3600.0
    ghi = run.ghi_at(t)
    run._leave_day()
    assert run.ghi_at(t) == ghi and 0.0 <= run.transmittance_at(t) <= 1.0
    energy = run.tally["dual-1"].energy()
    run._leave_day()  # once only: the day's energy is not counted twice
    assert run.tally["dual-1"].energy() == energy
