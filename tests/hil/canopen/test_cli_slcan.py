"""Acceptance: canopen's BaseNode402, in another process, loading the exported EDS, drives
``heliotrack hil drive --protocol canopen --link pty`` through its slcan pty to OPERATION
ENABLED and a target angle."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[3]
HELIOTRACK = [sys.executable, "-c", "import sys; from heliotrack.cli import main; sys.exit(main())"]


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    return env


@pytest.fixture
def canopen_drive_process():
    proc = subprocess.Popen(
        HELIOTRACK
        + [
            "hil",
            "drive",
            "--protocol",
            "canopen",
            "--link",
            "pty",
            "--id",
            "7",
            "--axes",
            "1",
            "--max-speed",
            "5",
            "--heartbeat-timeout",
            "0",
        ],
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
        cwd=REPO,
        env=_env(),
    )
    try:
        first = proc.stdout.readline().strip()
        assert first.startswith("PTY /dev/"), (first, proc.stderr.read() if proc.poll() else "")
        yield first.split(" ", 1)[1]
    finally:
        proc.send_signal(signal.SIGTERM)
        try:
            assert proc.wait(10) == 0
        finally:
            if proc.poll() is None:
                proc.kill()


def test_basenode402_in_another_process_drives_the_emulator_over_slcan(canopen_drive_process, tmp_path):
    from heliotrack.cli import main  # the same command, in-process: saves a 2 s start-up

    assert main(["protocol", "export", str(tmp_path)]) == 0
    eds = tmp_path / "heliotrack_drive.eds"
    assert eds.exists()
    out = subprocess.run(
        [sys.executable, "-m", "tests.hil.canopen.master_402", canopen_drive_process, str(eds), "7", "1.5"],
        capture_output=True,
        text=True,
        cwd=REPO,
        env=_env(),
        timeout=60,
        check=False,
    )
    report = json.loads(out.stdout.strip().splitlines()[-1])
    assert report["ok"], json.dumps(report) + out.stderr[-2000:]
    assert report["state"] == "OPERATION ENABLED"
    assert report["op_mode"] == "PROFILED POSITION"
    assert report["device_type"] & 0xFFFF == 0x192
    assert report["product_code"] == 0x4854
    assert report["position_deg"] == pytest.approx(1.5, abs=0.05)
    assert report["sdo_position_deg"] == pytest.approx(1.5, abs=0.05)
    assert report["consumer_heartbeat"] == (0x7F << 16) | 1000


def test_tcp_link_is_refused_for_canopen(capsys):
    from heliotrack.cli import main

    assert main(["hil", "drive", "--protocol", "canopen", "--link", "tcp"]) == 2
    assert "--link pty" in capsys.readouterr().err


def test_node_id_out_of_range_is_refused(capsys):
    from heliotrack.cli import main

    assert main(["hil", "drive", "--protocol", "canopen", "--id", "126", "--axes", "2"]) == 2
    assert "126" in capsys.readouterr().err


def test_a_canopen_link_on_slcan_drives_the_emulator_in_another_process(canopen_drive_process):
    """The controller's own backend, built from a ``[[links]]`` table through the registry,
    on the pty of ``heliotrack hil drive --protocol canopen`` (as on a USB-CAN adapter)."""
    import asyncio
    import time

    from controller.drives import open_drive
    from controller.drives.canopen import CanopenDrive
    from controller.drives.links import CanopenLink
    from firmware_protocol import Status

    link = CanopenLink(
        name="can-1", interface="slcan", channel=canopen_drive_process, bitrate=500000, timeout_s=0.5
    )
    drive = open_drive(link, 7)
    assert isinstance(drive, CanopenDrive)

    async def scenario():
        await drive.connect()
        try:
            assert drive.axis_count == 1
            state = await drive.exchange([2.5])
            assert state.axes[0].target_deg == pytest.approx(2.5)  # read back after the write
            deadline = time.monotonic() + 20.0  # 5 deg/s: about 1 s
            while not (state.axes[0].status & Status.AT_TARGET) and time.monotonic() < deadline:
                await asyncio.sleep(0.05)
                await drive.heartbeat()
                state = await drive.read_state()
            return state
        finally:
            await drive.close()

    state = asyncio.run(scenario())
    assert state.axes[0].actual_deg == pytest.approx(2.5, abs=0.05)
    assert drive.stats.errors == 0
