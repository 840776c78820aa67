"""``heliotrack run`` when nothing answers: a line (a pty nobody serves) with a drive and a
pyranometer on it.  The loop keeps cycling, the silent sensor is one warning (not one per
cycle) and a line at exit, the drive's safe position is reported as not confirmed, JSON
log lines parse; a second signal exits at once."""

from __future__ import annotations

import json
import signal
import time

import pytest

from heliotrack.cli import main
from hil.pty import PtyLink
from tests.heliotrack.plant_emulators import heliotrack


def _silent_plant(folder, port: str, timeout_s: float = 0.1, retries: int = 1):
    p = folder / "plant.toml"
    p.write_text(
        f"""
[site]
latitude = 32.5
longitude = 48.3

[control]
period_s = 1.0

[[links]]
name = "rs485"
kind = "modbus-rtu"
port = "{port}"
timeout_s = {timeout_s}
retries = {retries}

[[trackers]]
name = "dual-1"
type = "dual-axis"
link = "rs485"
device_id = 1

[pyranometer]
link = "rs485"
device_id = 10
"""
    )
    return p


@pytest.fixture
def silent_line():
    with PtyLink.open() as link:
        yield link.path


def test_a_silent_plant_logs_each_fault_once_and_a_summary(tmp_path, silent_line, capsys):
    cfg = _silent_plant(tmp_path, silent_line)
    rc = main(["--log-format", "json", "run", "--config", str(cfg), "--duration", "2.5"])
    assert rc == 0  # a stop on time, whatever the plant said
    records = [json.loads(line) for line in capsys.readouterr().err.splitlines()]  # every line JSON
    messages = [r["message"] for r in records]
    cycles = [r for r in records if r["message"].startswith("cycle ")]
    assert len(cycles) >= 3 and all(r["level"] == "INFO" and r["errors"] for r in cycles)
    pyr = [
        r for r in records if r["logger"].startswith("heliotrack") and r["message"].startswith("pyranometer:")
    ]
    assert len(pyr) == 1 and pyr[0]["level"] == "WARNING", messages  # once, not once per cycle
    safe = next(r for r in records if r["message"].startswith("dual-1: no answer"))
    assert safe["level"] == "WARNING" and "its watchdog stows it within" in safe["message"]
    summary = next(r for r in records if r["message"].startswith("stopped (end of --duration)"))
    assert (
        summary["cycles"] == len(cycles) and summary["safe_confirmed"] == 0 and summary["sensor_errors"] >= 3
    )
    assert "pyranometer" in summary["sensors_down"]
    assert any(m.startswith("pyranometer still not answering at exit") for m in messages)


def test_a_second_signal_exits_at_once(tmp_path, silent_line):
    # slow answers (3 attempts of 1 s): the drive's safe position takes seconds to give up on
    cfg = _silent_plant(tmp_path, silent_line, timeout_s=1.0, retries=2)
    proc = heliotrack("run", "--config", str(cfg))
    try:
        first = proc.stderr.readline()
        assert "heliotrack run:" in first, first
        proc.send_signal(signal.SIGTERM)
        time.sleep(1.0)  # start-up cancelled, the safe position under way
        assert proc.poll() is None
        proc.send_signal(signal.SIGINT)
        t = time.monotonic()
        rc = proc.wait(5)
        assert time.monotonic() - t < 1.0
    finally:
        if proc.poll() is None:
            proc.kill()
    err = proc.stderr.read()
    assert rc == 128 + signal.SIGINT, err
    assert "second signal (SIGINT): exiting at once" in err and "Traceback" not in err


def test_a_port_that_refuses_its_settings_still_ends_in_a_safe_shutdown(tmp_path, silent_line, capsys):
    """An audit's case: ``parity = "E"`` on a pty raised ``termios.error`` at start-up ("the
    control loop failed") and again in the shutdown, which never wrote its record: exit 1,
    learned state not saved."""
    cfg = _silent_plant(tmp_path, silent_line)
    cfg.write_text(cfg.read_text().replace("retries = 1\n", 'retries = 1\nparity = "E"\n'))
    rc = main(["run", "--config", str(cfg), "--state", str(tmp_path / "state"), "--duration", "1.5"])
    err = capsys.readouterr().err
    assert rc == 0 and "Traceback" not in err and "the control loop failed" not in err, err
    assert "cannot configure the port (baudrate 115200, parity E, stopbits 1): Invalid argument" in err
    assert "stopped (end of --duration)" in err and "safe position confirmed for 0 of 1 drives" in err
    # written: its watchdog stows it, and the next start resumes that stow
    assert json.loads((tmp_path / "state" / "shutdown.json").read_text())["stowed"] == ["dual-1"]
