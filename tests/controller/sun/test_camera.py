"""Frame folders: names carry the time (any documented form), the newest frame not later
than the request and not older than max_age_s is handed out, unreadable files give none."""

import cv2
import numpy as np
import pytest

from controller.errors import ConfigError
from controller.sun.camera import CameraSunSensor, FolderFrameSource
from controller.timestamps import format_name_time, time_from_name

T0 = 1774001700.0  # 2026-03-20T10:15:00Z


def _frames(folder, times, names=None):
    folder.mkdir(exist_ok=True)
    for i, t in enumerate(times):
        name = names[i] if names else format_name_time(t) + ".png"
        cv2.imwrite(str(folder / name), np.full((4, 6), i * 10, np.uint8))


def test_grab_returns_the_newest_frame_not_later_than_t(tmp_path):
    _frames(tmp_path / "f", [T0, T0 + 60, T0 + 120.5])
    src = FolderFrameSource(tmp_path / "f", max_age_s=90)
    assert src.grab(T0 - 1) is None
    f = src.grab(T0 + 59.9)
    assert f.time == T0 and f.image.shape == (4, 6) and f.image[0, 0] == 0
    assert src.grab(T0 + 60).time == T0 + 60
    assert src.grab(T0 + 121).time == pytest.approx(T0 + 120.5)
    assert src.grab(T0 + 120.5 + 90.1) is None  # too old
    assert f.name == "2026-03-20T10-15-00Z.png"


def test_every_documented_name_form_is_read(tmp_path):
    names = [
        "2026-03-20T10-15-00Z.png",
        "cam_20260320T101600Z.png",
        "2026-03-20_10-17-00.png",
        "2026-03-20T13:48:00+03:30.png",
    ]
    _frames(tmp_path / "f", range(4), names)
    src = FolderFrameSource(tmp_path / "f")
    assert list(src.times) == [T0, T0 + 60, T0 + 120, T0 + 180]
    assert [time_from_name(n) for n in names] == list(src.times)


def test_files_without_a_timestamp_are_refused_by_name(tmp_path):
    _frames(tmp_path / "f", [0], ["IMG_0001.png"])
    with pytest.raises(ConfigError, match="IMG_0001.png"):
        FolderFrameSource(tmp_path / "f")
    with pytest.raises(ConfigError, match="a folder"):
        FolderFrameSource(tmp_path / "missing")


def test_a_truncated_frame_is_no_frame_and_is_counted(tmp_path):
    _frames(tmp_path / "f", [T0])
    path = tmp_path / "f" / (format_name_time(T0) + ".png")
    path.write_bytes(path.read_bytes()[:20])

    class Never:
        def estimate_image(self, image, t):  # pragma: no cover - must not be called
            raise AssertionError("a broken frame reached the estimator")

    sensor = CameraSunSensor(FolderFrameSource(tmp_path / "f"), Never())
    assert sensor.observe(T0 + 1) is None
    assert sensor.outcomes["no frame"] == 1


def test_a_frame_cut_short_at_the_end_is_no_frame(tmp_path):
    _frames(tmp_path / "f", [T0])
    path = tmp_path / "f" / (format_name_time(T0) + ".png")
    path.write_bytes(path.read_bytes()[:-12])  # IEND gone: OpenCV would decode it
    assert FolderFrameSource(tmp_path / "f").grab(T0) is None
