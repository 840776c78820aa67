"""``heliotrack run`` and ``check`` with a panel camera: the panel-mounted closed loop on a
plant, against ``heliotrack hil drive --panel-camera`` in another process (a Modbus TCP
row whose panel sits 1.5 deg off its shaft, its camera writing timestamped frames into a
folder on the wall clock).  The row is put where the sun stands near the zenith now, so
the test runs at any hour; truth from pvlib (SPA and ``tracking.singleaxis``), the
drive's target read from the emulator itself.

The tests share the emulator and run in order (the second run resumes the first's offset).
"""

from __future__ import annotations

import json
import re
import signal
import time

import pytest

from heliotrack.cli import main
from tests.heliotrack.plant_emulators import Drive as EmulatorDrive
from tests.heliotrack.plant_emulators import read_axes, start_camera_drive
from tests.heliotrack.test_run_plant import Run

OFFSET = 1.5  # deg: the panel minus its shaft
PERIOD_S = 2.0
LENS = "config/calibration/panel-fisheye.toml"


def plant(folder, port: int, site, frames: str):
    from tests.conftest import REPO

    path = folder / f"plant-{abs(hash(frames))}.toml"
    (folder / "lenses").mkdir(exist_ok=True)  # each camera's own bundle, as on a plant
    (folder / "lenses" / "row-1.toml").write_text((REPO / LENS).read_text())
    path.write_text(
        f"""
[site]
name = "panel-camera plant"
latitude = {site[0]}
longitude = {site[1]}
altitude = 0.0

[control]
period_s = {PERIOD_S}
heartbeat_timeout_s = 6.0
sun_source = "ephemeris"

[[links]]
name = "lan"
kind = "modbus-tcp"
host = "127.0.0.1"
tcp_port = {port}

[[trackers]]
name = "row-1"
type = "single-axis"
link = "lan"
device_id = 1
axis_azimuth = 180.0
max_angle = 55.0
gcr = 0.4
safe_position = "hold"

[closedloop]
calibration = "lenses/{{tracker}}.toml"
frames = "{frames}"
"""
    )
    return path


def sun_rotation(t: float, site) -> float:
    """The rotation (deg) that points a true north-south row at the sun at ``t`` (pvlib)."""
    import pandas as pd
    import pvlib

    times = pd.DatetimeIndex([pd.Timestamp(t, unit="s", tz="UTC")])
    sp = pvlib.solarposition.get_solarposition(times, site[0], site[1], altitude=0.0)
    tr = pvlib.tracking.singleaxis(
        sp["apparent_zenith"], sp["azimuth"], axis_tilt=0.0, axis_azimuth=180.0, max_angle=55.0, gcr=0.4
    )
    return float(tr["tracker_theta"].iloc[0])


@pytest.fixture(scope="module")
def row(tmp_path_factory):
    """(the emulator as a drive to read, its site, the folder of the plant and state)."""
    folder = tmp_path_factory.mktemp("panel")
    cam = start_camera_drive(
        folder / "panelcams" / "row-1", "--mount-offset", str(OFFSET), "--max-speed", "5"
    )
    try:
        yield EmulatorDrive(cam.proc, "tcp", str(cam.port), 1, 1), cam.site, folder
    finally:
        if cam.proc.poll() is None:
            cam.proc.send_signal(signal.SIGTERM)
        cam.proc.communicate(timeout=10)


def test_check_shows_the_panel_cameras_frame_and_the_sun_off_the_normal(row, capsys):
    drive, site, folder = row
    time.sleep(2.5)  # the emulator's first frames
    cfg = plant(folder, int(drive.address), site, str(folder / "panelcams" / "{tracker}"))
    assert main(["check", "--config", str(cfg)]) == 0
    out = capsys.readouterr().out
    line = next(ln for ln in out.splitlines() if ln.startswith("row-1/camera"))
    assert " ok " in line and "frame 320x240" in line, out
    # the shaft at its stow (0), the panel 1.5 deg further: the sun that far off its normal
    off = float(re.search(r"the sun (\d+\.\d+) deg from the panel's normal", line).group(1))
    assert abs(off - abs(sun_rotation(time.time(), site) - OFFSET)) < 0.6, line


def run_until(cfg, folder, row, cycle: int):
    """``heliotrack run`` until its cycle ``cycle``, then SIGTERM: (its log, the row's axis as
    the emulator reports it then, pvlib's rotation for the sun then)."""
    drive, site, _ = row
    run = Run(cfg, folder / "state")
    try:
        run.wait_line(rf" cycle {cycle}: ", timeout=20 + 4 * cycle * PERIOD_S)
        axis = read_axes(drive)[0]
        truth = sun_rotation(time.time(), site)
        run.proc.send_signal(signal.SIGTERM)
        assert run.proc.wait(15) == 0
    finally:
        if run.proc.poll() is None:
            run.proc.kill()
    log = run.text()
    assert "Traceback" not in log, log
    return log, axis, truth


def test_run_learns_the_rows_offset_and_points_the_panel_at_the_sun(row):
    drive, site, folder = row
    cfg = plant(folder, int(drive.address), site, str(folder / "panelcams" / "{tracker}"))
    log, axis, truth = run_until(cfg, folder, row, cycle=12)
    # the panel (shaft + 1.5) on the sun: the shaft's target 1.5 deg short of it
    assert axis.target_deg == pytest.approx(truth - OFFSET, abs=0.2), (axis, truth, log)
    summary = re.search(r"closed loop row-1: learned offset rotation ([-+]\d+\.\d+) deg.*frames (.*)", log)
    assert summary, log
    assert float(summary.group(1)) == pytest.approx(-OFFSET, abs=0.1), summary.group(0)
    assert int(re.search(r"found (\d+)", summary.group(2)).group(1)) >= 8, summary.group(0)
    # each cycle says what set the row's setpoint: the camera, once the drive has arrived
    assert re.search(r" cycle \d+: TRACK; .*; closed loop row-1 camera; 0 error", log), log
    saved = json.loads((folder / "state" / "misalignment.json").read_text())
    assert saved["rows"]["row-1"]["rotation"]["estimate_deg"] == pytest.approx(-OFFSET, abs=0.1)


def test_a_restart_without_frames_keeps_the_learned_offset(row):
    drive, site, folder = row
    (folder / "blind" / "row-1").mkdir(parents=True)  # a camera that gives nothing
    cfg = plant(folder, int(drive.address), site, str(folder / "blind" / "{tracker}"))
    log, axis, truth = run_until(cfg, folder, row, cycle=4)
    resumed = re.search(r"row-1 starts from its learned offset rotation ([-+]\d+\.\d+) deg", log)
    assert resumed and float(resumed.group(1)) == pytest.approx(-OFFSET, abs=0.1), log
    assert axis.target_deg == pytest.approx(truth - OFFSET, abs=0.2), (axis, truth, log)
    assert re.search(r"closed loop row-1: .*setpoints learned \d+.*; frames no frame \d+$", log, re.M), log
    assert re.search(r" cycle 4: TRACK; .*; closed loop row-1 learned; 0 error", log), log
