"""The console script end to end, as a user runs it."""

import json
import signal
import subprocess
import sys
import time
from pathlib import Path

import minimalmodbus
import pytest

from firmware_protocol import Mode, Status, register
from heliotrack.cli import main
from tests.conftest import DEFAULT_CONFIG, REPO

HELIOTRACK = [sys.executable, "-m", "heliotrack.cli"]


def short_config(tmp_path: Path, period: float = 300.0) -> Path:
    text = DEFAULT_CONFIG.read_text().replace("period_s = 60.0", f"period_s = {period}")
    text = text.replace("enabled = true ", "enabled = false ")  # DIFFUSE needs 1-min samples
    p = tmp_path / "scenario.toml"
    p.write_text(text)
    return p


def test_simulate_writes_summary_and_log(tmp_path, capsys):
    out = tmp_path / "out"
    rc = main(
        [
            "simulate",
            "--config",
            str(short_config(tmp_path)),
            "--days",
            "1",
            "--start",
            "2024-06-21",
            "--out",
            str(out),
        ]
    )
    assert rc == 0
    s = json.loads((out / "summary.json").read_text())
    assert s["days"] == 1 and s["cycles"] == 288 and s["start"] == "2024-06-21"
    for key in ("mean", "p95", "max"):
        assert s["pointing_error_deg"][key] is not None
    # A 5-minute period leads/lags the sun by up to ~0.6 deg; tracking must stay that close.
    assert s["pointing_error_deg"]["p95"] < 0.8
    assert 0.99 < s["energy_ratio"] <= 1.001
    assert s["modbus"]["errors"] == 0 and s["modbus"]["transactions"] > 288 * 2
    assert set(s["trackers"]) == {"dual-1", "row-1"}
    lines = (out / "cycles.csv").read_text().splitlines()
    assert len(lines) == 1 + 288 * 2
    assert "time_utc,tracker,mode" in lines[0]
    text = capsys.readouterr().out
    assert "dual-1" in text and "modbus:" in text


def test_bad_config_is_a_clear_error_not_a_traceback(tmp_path):
    bad = tmp_path / "bad.toml"
    bad.write_text(DEFAULT_CONFIG.read_text().replace("latitude = 32.4835", "latitude = 132.4835"))
    r = subprocess.run(
        [*HELIOTRACK, "simulate", "--config", str(bad), "--out", str(tmp_path)],
        capture_output=True,
        text=True,
    )
    assert r.returncode == 2
    assert "site.latitude" in r.stderr and str(bad) in r.stderr
    assert "Traceback" not in r.stderr
    assert not (tmp_path / "summary.json").exists()


def test_protocol_export(tmp_path, capsys):
    assert main(["protocol", "export", str(tmp_path)]) == 0
    assert (tmp_path / "REGISTERS.md").read_text().startswith("# heliotrack drive")
    assert "#define HT_MAGIC 0x4854u" in (tmp_path / "heliotrack_drive.h").read_text()


@pytest.fixture
def standalone_drive():
    proc = subprocess.Popen(
        [
            *HELIOTRACK,
            "hil",
            "drive",
            "--link",
            "pty",
            "--axes",
            "2",
            "--id",
            "5",
            "--heartbeat-timeout",
            "1.0",
            "--max-speed",
            "5",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        first = proc.stdout.readline().strip()
        assert first.startswith("PTY /dev/"), first
        yield proc, first.split(" ", 1)[1]
    finally:
        if proc.poll() is None:
            proc.send_signal(signal.SIGTERM)
            proc.wait(10)


def test_standalone_drive_with_an_independent_master(standalone_drive):
    proc, path = standalone_drive
    m = minimalmodbus.Instrument(path, 5)
    m.serial.baudrate = 115200
    m.serial.timeout = 0.5
    assert m.read_registers(0, 3) == [0x4854, 0x0100, 2]
    target = register("TARGET_ANGLE").address(1)
    m.write_long(target, 60_000, signed=True)  # 60.000 deg elevation
    assert m.read_long(target, signed=True) == 60_000
    # Keep the watchdog fed while the axis moves there.
    hb = register("HEARTBEAT").address()
    deadline = time.time() + 15
    beat = 0
    while time.time() < deadline:
        beat += 1
        m.write_register(hb, beat)
        if m.read_register(register("STATUS").address(1)) & Status.AT_TARGET:
            break
        time.sleep(0.2)
    assert m.read_long(register("ACTUAL_ANGLE").address(1), signed=True) == pytest.approx(60_000, abs=30)
    # Stop the heartbeat: the firmware stows by itself.
    time.sleep(1.6)
    status = Status(m.read_register(register("STATUS").address(1)))
    assert status & Status.COMM_LOST
    assert m.read_register(register("MODE").address(1)) == Mode.STOW
    deadline = time.time() + 15
    while (
        time.time() < deadline and not Status(m.read_register(register("STATUS").address(1))) & Status.STOWED
    ):
        time.sleep(0.2)
    assert Status(m.read_register(register("STATUS").address(1))) & Status.STOWED
    assert m.read_long(register("ACTUAL_ANGLE").address(1), signed=True) == pytest.approx(90_000, abs=30)
    m.serial.close()
    proc.send_signal(signal.SIGTERM)
    assert proc.wait(10) == 0


def test_hil_drive_rejects_bad_arguments():
    r = subprocess.run([*HELIOTRACK, "hil", "drive", "--id", "300"], capture_output=True, text=True)
    assert r.returncode == 2 and "--id" in r.stderr and "Traceback" not in r.stderr


def test_realtime_simulation_serves_sunspec_to_a_scada_client(tmp_path):
    from sunspec2.modbus.client import SunSpecModbusClientDeviceTCP
    from sunspec2.modbus.modbus import ModbusClientException

    cfg = short_config(tmp_path, period=1.0)
    proc = subprocess.Popen(
        [
            *HELIOTRACK,
            "simulate",
            "--config",
            str(cfg),
            "--realtime",
            "--duration",
            "8",
            "--sunspec",
            "127.0.0.1:0",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        first = proc.stdout.readline().strip()
        assert first.startswith("SUNSPEC 127.0.0.1:"), first + proc.stderr.read()
        port = int(first.rsplit(":", 1)[1])
        proc.stdout.readline()  # wait for a first cycle
        dev = SunSpecModbusClientDeviceTCP(slave_id=1, ipaddr="127.0.0.1", ipport=port, timeout=2)
        dev.scan()
        try:
            assert 1 in dev.models and 601 in dev.models
            m = dev.models[601][0]
            m.read()
            assert [m.tracker[i].Id.value for i in range(m.N.value)] == ["dual-1", "row-1"]
            assert m.tracker[0].ElPos.cvalue is not None
            blk = m.tracker[0]
            blk.Ctl.value = 1
            with pytest.raises(ModbusClientException, match="exception: 1"):
                blk.write()  # writes are off unless configured
        finally:
            dev.close()
        out, err = proc.communicate(timeout=30)
        assert proc.returncode == 0, err
        assert "0 operator overrides" in out and "row errors" in out
    finally:
        if proc.poll() is None:
            proc.kill()


def test_sunspec_needs_realtime(tmp_path):
    r = subprocess.run(
        [*HELIOTRACK, "simulate", "--sunspec", "127.0.0.1:1502"], capture_output=True, text=True
    )
    assert r.returncode == 2 and "--realtime" in r.stderr


@pytest.mark.parametrize(
    "argv, message",
    [
        (["--duration", "5"], "--duration: expected --realtime as well"),  # was a whole day, silently
        (
            ["--realtime", "--duration", "5", "--out", "rt"],
            "--out: expected no output folder with --realtime",
        ),
    ],
)
def test_simulate_refuses_options_it_would_ignore(tmp_path, capsys, argv, message):
    cfg = short_config(tmp_path)
    assert main(["simulate", "--config", str(cfg), *argv]) == 2
    assert message in capsys.readouterr().err and not (tmp_path / "rt").exists()


def test_a_run_of_some_hours_says_hours_not_days():
    from heliotrack.output import span_text

    assert span_text({"days": 1, "hours": 1.0}) == "1 hour(s)"
    assert span_text({"days": 2, "hours": 48.0}) == "2 day(s)"


def test_output_piped_into_head_is_no_traceback(tmp_path):
    """`simulate | head -1` had ended in a BrokenPipeError traceback, exit 1 (`true` reads
    nothing, so that the pipe is closed before the first line whatever the timing)."""
    import subprocess

    cmd = f"{sys.executable} -m heliotrack.cli simulate --hours 1 --no-report --out {tmp_path / 'o'} | true"
    r = subprocess.run(
        ["bash", "-c", cmd + "; echo rc=${PIPESTATUS[0]}"], capture_output=True, text=True, cwd=REPO
    )
    assert "Traceback" not in r.stderr and "rc=141" in r.stdout, (r.stdout, r.stderr)
    assert (tmp_path / "o" / "summary.json").is_file()


@pytest.mark.parametrize("command", [["simulate"], ["hil", "record"]])
def test_days_and_hours_together_are_refused(tmp_path, capsys, command):
    """`hil record --days 2 --hours 0.1` had recorded 0.1 h without a word."""
    argv = [*command, "--days", "2", "--hours", "0.1", "--out", str(tmp_path / "o")]
    if command == ["hil", "record"]:
        argv += ["--config", str(REPO / "config" / "hil-hotspot.toml")]
    assert main(argv) == 2
    assert "--days: expected --days or --hours, not both" in capsys.readouterr().err
