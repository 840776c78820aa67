"""``heliotrack hil drive --panel-camera DIR``: a fisheye camera on the panel the emulated
drive turns writes timestamped frames into DIR, in another process, on the wall clock.

The site is put where the sun is at the zenith now (latitude: today's declination,
longitude: where it is solar noon), so a row at rotation 0 sees the sun near the image's
centre whatever the hour or the date, and a mounting offset moves it ~1.45 px per deg.
"""

from __future__ import annotations

import shutil
import signal
import subprocess
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from tests.heliotrack.plant_emulators import HELIOTRACK, Drive, env, read_axes, start_camera_drive, wait_for

OFFSET = 2.0  # deg: ~2.9 px on the 320 x 240 panel lens


@pytest.fixture
def processes():
    """Processes to end after the test, whatever it asserted."""
    started: list[subprocess.Popen] = []
    yield started
    for proc in started:
        if proc.poll() is None:
            proc.kill()
        proc.communicate()


def frames(folder: Path) -> list[Path]:
    return sorted(folder.glob("*.png"))


def terminate(proc: subprocess.Popen, timeout: float = 5.0) -> tuple[int, str, float]:
    """SIGTERM; (exit code, stderr, seconds it took to exit)."""
    t0 = time.monotonic()
    proc.send_signal(signal.SIGTERM)
    _, err = proc.communicate(timeout=timeout)
    return proc.returncode, err, time.monotonic() - t0


def sun_centroid(image: np.ndarray) -> np.ndarray:
    """Centroid (px) of the largest saturated blob: the sun's glare."""
    saturated = (image.min(axis=2) >= 250).astype(np.uint8)
    n, _, stats, centroids = cv2.connectedComponentsWithStats(saturated)
    assert n > 1, "no saturated sun in the frame"
    return centroids[1 + int(np.argmax(stats[1:, cv2.CC_STAT_AREA]))]


def predicted_sun(
    t: float, site: tuple[float, float], rotation: float, mount: tuple[float, float, float] = (0.0, 0.0, 0.0)
) -> np.ndarray:
    """Where the truth sun (pvlib SPA) falls on the panel lens of a north-south row at
    ``rotation`` deg, the camera turned on the panel by ``mount`` (px)."""
    from hil.camera import Site
    from hil.panelcam import PanelCamera, panel_lens
    from hil.truth import sun_truth

    sun = sun_truth(np.array([t]), site[0], site[1]).vectors[0]
    cam = PanelCamera("single-axis", Site(site[0], site[1], 0.0), mount_deg=mount)
    cam_from_enu = cam.enu_from_camera([rotation]).T
    uv, inside = panel_lens(0.5).project(cam_from_enu @ sun)
    assert inside[0]
    return uv[0]


def test_frames_show_the_sun_where_the_panel_with_its_offset_points(tmp_path, processes):
    from controller.sun.camera import FolderFrameSource
    from controller.timestamps import time_from_name

    folder = tmp_path / "new" / "frames"  # created by the emulator
    drive = start_camera_drive(
        folder, "--mount-offset", str(OFFSET), "--camera-mount", "0", "1.5", "0", "--camera-interval", "1"
    )
    processes.append(drive.proc)
    got = wait_for(lambda: frames(folder)[-2:] if len(frames(folder)) >= 2 else [], 10.0)
    assert len(got) == 2, list(folder.iterdir()) if folder.exists() else "no folder"
    for path in got:
        t = time_from_name(path.name)
        assert t is not None and abs(t - time.time()) < 5.0, path.name
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        assert image.shape == (240, 320, 3) and image.dtype == np.uint8
        assert np.abs(image[..., 0].astype(int) - image[..., 2]).max() > 10  # colour, not grey
        seen = sun_centroid(image)
        # the drive holds its stow angle 0: the panel is at 0 + the mounting offset, and the
        # camera turned 1.5 deg on it
        mount = (0.0, 1.5, 0.0)
        assert np.hypot(*(seen - predicted_sun(t, drive.site, 0.0 + OFFSET, mount))) < 1.0
        assert np.hypot(*(seen - predicted_sun(t, drive.site, 0.0, mount))) > 2.0  # the offset shows
        assert np.hypot(*(seen - predicted_sun(t, drive.site, 0.0 + OFFSET))) > 1.5  # and the turn
    # the controller's reader takes them as they come
    frame = FolderFrameSource(folder).grab(time.time())
    assert frame is not None and frame.image.shape[:2] == (240, 320)
    code, err, _ = terminate(drive.proc)
    assert code == 0, err
    assert "panel camera: " in err and "+2.00 deg" in err and "camera turned +0.00 +1.50 +0.00 deg" in err


def test_only_the_newest_frames_are_kept(tmp_path, processes):
    folder = tmp_path / "frames"
    folder.mkdir()
    (folder / "notes.txt").write_text("not a frame: stays")
    (folder / "2020-01-01T00-00-00Z.png").write_bytes(b"an old frame: goes")
    (folder / ".2020-01-01T00-00-01Z.png.part").write_bytes(b"a killed writer's: goes")
    proc = start_camera_drive(folder, "--keep", "3", "--camera-interval", "1").proc
    processes.append(proc)
    t0 = time.time()
    assert wait_for(lambda: frames(folder) and frames(folder)[-1].name > _name(t0 + 5.0), 12.0)
    kept = frames(folder)
    assert 3 <= len(kept) <= 4, kept  # a fourth only between its rename and the pruning
    assert kept[0].name > _name(t0 + 1.0)  # the first ones, and the old one, went
    assert (folder / "notes.txt").exists()
    assert len(list(folder.glob(".*.part"))) <= 1  # the one in flight
    assert terminate(proc)[0] == 0


def _name(t: float) -> str:
    from hil.skycam.dataset import frame_name

    return frame_name(t)


@pytest.mark.parametrize(
    "options, says",
    [
        (["--panel-camera", "{dir}"], "--site"),
        (["--panel-camera", "{dir}", "--site", "20", "0", "--camera-interval", "0.5"], "--camera-interval"),
        (["--panel-camera", "{dir}", "--site", "20", "0", "--mount-offset", "1", "2"], "--mount-offset"),
        (["--panel-camera", "{dir}", "--site", "95", "0"], "--site"),
        (["--panel-camera", "{dir}", "--site", "20", "181"], "--site"),
        (["--panel-camera", "{dir}", "--site", "20", "0", "--keep", "1"], "--keep"),
        (
            ["--panel-camera", "{dir}", "--site", "20", "0", "--camera-mount", "0", "200", "0"],
            "--camera-mount",
        ),
    ],
)
def test_a_bad_camera_option_is_one_line(tmp_path, capsys, options, says):
    from heliotrack.cli import main

    folder = tmp_path / "frames"
    args = ["hil", "drive", "--axes", "1", *(o.replace("{dir}", str(folder)) for o in options)]
    assert main(args) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and says in err and "Traceback" not in err, err
    assert not folder.exists()  # refused before anything was made


def test_a_bad_camera_option_exits_2_from_the_command_line(tmp_path):
    r = subprocess.run(
        [*HELIOTRACK, "hil", "drive", "--panel-camera", str(tmp_path / "f")],
        capture_output=True,
        text=True,
        env=env(),
        timeout=30,
    )
    assert r.returncode == 2 and "--site" in r.stderr and "Traceback" not in r.stderr, r.stderr
    assert r.stderr.strip().count("\n") == 0


def test_sigterm_ends_drive_and_camera_promptly(tmp_path, processes):
    folder = tmp_path / "frames"
    proc = start_camera_drive(folder).proc
    processes.append(proc)
    assert wait_for(lambda: frames(folder), 10.0)
    code, err, took = terminate(proc, timeout=10.0)
    assert code == 0 and took < 5.0, (code, took, err)
    assert err.strip().splitlines()[-1].startswith("drive stopped: axis 0 0.00 deg"), err
    assert "Traceback" not in err and not list(folder.glob(".*.part"))


def test_a_lost_folder_is_one_warning_and_the_drive_serves_on(tmp_path, processes):
    folder = tmp_path / "frames"
    camera_drive = start_camera_drive(folder)
    proc = camera_drive.proc
    processes.append(proc)
    assert wait_for(lambda: frames(folder), 10.0)
    shutil.rmtree(folder)  # unmounted, or removed by hand
    time.sleep(2.5)  # two frames due
    drive = Drive(proc, "tcp", str(camera_drive.port), 1, 1)
    assert read_axes(drive)[0].actual_deg == pytest.approx(0.0, abs=0.01)
    code, err, _ = terminate(proc)
    assert code == 0, err
    warnings = [line for line in err.splitlines() if "panel camera: warning" in line]
    assert len(warnings) == 1 and str(folder) in warnings[0], err
    assert err.strip().splitlines()[-1].startswith("drive stopped:"), err
