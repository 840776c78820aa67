"""Frame sources of ``heliotrack run``: a video file played on the clock, a live stream read
by OpenCV (a real HTTP stream that drops and comes back), a folder that grows while the
loop runs, and frames judged before any estimator sees them."""

from __future__ import annotations

import functools
import http.server
import logging
import threading
import time

import cv2
import numpy as np
import pytest

from controller.clock import SimClock
from controller.errors import ConfigError
from controller.sun.camera import (
    CameraSunSensor,
    FolderFrameSource,
    VideoCaptureFrameSource,
    capture_target,
)
from controller.timestamps import format_name_time

T0 = 1774001700.0  # 2026-03-20T10:15:00Z


def _video(path, values, fps):
    w = cv2.VideoWriter(str(path), cv2.VideoWriter_fourcc(*"FFV1"), fps, (64, 48), isColor=False)
    for v in values:
        w.write(np.full((48, 64), v, np.uint8))
    w.release()
    return path


def test_a_video_file_plays_at_its_frame_rate_from_when_it_was_opened(tmp_path):
    clock = SimClock(T0)
    src = VideoCaptureFrameSource(str(_video(tmp_path / "v.avi", [10, 60, 110, 160, 210], 2.0)), clock)
    assert not src.live and src.fps == pytest.approx(2.0)
    f = src.grab(clock.now())
    assert f.image.ndim == 2 and f.image.dtype == np.uint8 and f.image[0, 0] == 10  # grey, 8 bit
    assert f.time == T0 and f.name == "v.avi#0"
    clock.sleep(0.5)
    assert src.grab(clock.now()).image[0, 0] == 60
    clock.sleep(1.0)  # frame 3: frame 2 is skipped
    f = src.grab(clock.now())
    assert f.image[0, 0] == 160 and f.time == pytest.approx(T0 + 1.5)
    clock.sleep(3.0)  # past the end: the last frame, until it is too old
    assert src.grab(clock.now()).image[0, 0] == 210
    clock.sleep(src.max_age_s)
    assert src.grab(clock.now()) is None
    src.close()
    # a frame every 20 s: each is the newest until the next, not "no frame" after 10 s
    slow = VideoCaptureFrameSource(str(_video(tmp_path / "slow.avi", [10, 60], 0.05)), clock)
    clock.sleep(15.0)
    assert slow.grab(clock.now()).image[0, 0] == 10
    clock.sleep(10.0)
    assert slow.grab(clock.now()).image[0, 0] == 60
    slow.close()


def test_what_frames_names_is_read_as_opencv_opens_it(tmp_path):
    assert capture_target("device:2") == (2, True)
    assert capture_target("rtsp://10.0.0.9/stream1") == ("rtsp://10.0.0.9/stream1", True)
    video = _video(tmp_path / "v.avi", [0], 1.0)
    assert capture_target(str(video)) == (str(video), False)
    with pytest.raises(ConfigError, match="device:N"):
        capture_target("device:front")
    with pytest.raises(ConfigError, match="hotspot.frames"):
        capture_target(str(tmp_path / "missing.avi"))
    (tmp_path / "junk.avi").write_bytes(b"not a video")
    with pytest.raises(ConfigError, match="a video file OpenCV can read"):
        VideoCaptureFrameSource(str(tmp_path / "junk.avi"))


class _Quiet(http.server.SimpleHTTPRequestHandler):
    def log_message(self, *args):
        pass


def _serve(folder, port=0):
    server = http.server.ThreadingHTTPServer(
        ("127.0.0.1", port), functools.partial(_Quiet, directory=str(folder))
    )
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server


def _until(predicate, timeout=10.0):
    deadline = time.monotonic() + timeout
    while not predicate() and time.monotonic() < deadline:
        time.sleep(0.02)
    return predicate()


def test_a_stream_that_drops_is_reopened_with_backoff(tmp_path, caplog):
    """An HTTP stream (ffmpeg through OpenCV) that ends and whose server goes away: the
    reader reopens it with growing backoff, warns, and picks up when it is back."""
    caplog.set_level(logging.INFO, logger="heliotrack.camera")
    _video(tmp_path / "v.avi", [50, 100, 150], 10.0)
    server = _serve(tmp_path)
    port = server.server_address[1]
    src = VideoCaptureFrameSource(f"http://127.0.0.1:{port}/v.avi", min_backoff_s=0.05, max_backoff_s=0.2)
    try:
        assert src.live
        f = src.first_frame(time.time(), timeout_s=10)
        assert f is not None and f.image.shape == (48, 64) and f.image.dtype == np.uint8
        assert abs(f.time - time.time()) < 5  # stamped on arrival, wall clock
        # the stream ends after three frames: it is opened again and again
        assert _until(lambda: src.opens >= 3), src.opens
        server.shutdown()
        server.server_close()
        time.sleep(0.5)
        opens, read = src.opens, src.frames_read
        time.sleep(0.5)
        assert (src.opens, src.frames_read) == (opens, read)  # nothing to open now
        assert src.grab(time.time() + src.max_age_s + 1) is None  # the last frame has aged
        assert "no frames" in caplog.text
        server = _serve(tmp_path, port)  # back: frames again, without anyone asking
        assert _until(lambda: src.frames_read > read), "not reopened after the server came back"
        assert "frames again" in caplog.text
    finally:
        src.close()
        server.shutdown()
        server.server_close()
    assert not src._thread.is_alive()


def test_a_camera_that_is_not_there_gives_no_frame_and_a_warning(caplog):
    caplog.set_level(logging.WARNING, logger="heliotrack.camera")
    src = VideoCaptureFrameSource("device:63", min_backoff_s=0.05, max_backoff_s=0.1)
    try:
        assert src.first_frame(time.time(), timeout_s=0.3) is None
        assert src.grab(time.time()) is None
        assert _until(lambda: "device:63: no frames" in caplog.text, 5)
    finally:
        t = time.monotonic()
        src.close()
    assert time.monotonic() - t < 2
    assert caplog.text.count("device:63: no frames") == 1  # one warning per outage


def _png(folder, t, value=0, shape=(48, 64)):
    folder.mkdir(exist_ok=True)
    cv2.imwrite(str(folder / (format_name_time(t) + ".png")), np.full(shape, value, np.uint8))


def test_a_folder_is_watched_for_frames_added_after_start(tmp_path, caplog):
    _png(tmp_path / "f", T0, 40)
    src = FolderFrameSource(tmp_path / "f")
    assert src.grab(T0 + 30).time == T0
    _png(tmp_path / "f", T0 + 20, 80)  # the camera writes a new frame
    f = src.grab(T0 + 30)
    assert f.time == T0 + 20 and f.image[0, 0] == 80
    cv2.imwrite(str(tmp_path / "f" / "snapshot.png"), np.zeros((4, 4), np.uint8))  # no time in its name
    assert src.grab(T0 + 30).time == T0 + 20  # skipped, with a warning, not an exception
    assert "snapshot.png has no timestamp" in caplog.text
    assert src.first_frame(T0 + 10_000).time == T0 + 20  # however old, for check


class _Recorder:
    """An estimator that records what it was given and finds nothing."""

    def __init__(self):
        self.images = []

    def estimate_image(self, image, t):
        self.images.append(image)

        class Result:
            reason = "no_glint"

            def observation(self):
                return None

        return Result()


def test_frames_are_judged_before_the_estimator_sees_them(tmp_path):
    est = _Recorder()
    folder = tmp_path / "f"
    _png(folder, T0, 3)  # black: a lens cap, a dead sensor
    sensor = CameraSunSensor(FolderFrameSource(folder), est)
    assert sensor.observe(T0 + 1) is None and sensor.last_outcome == "black_frame"
    _png(folder, T0 + 10, 255)  # saturated
    assert sensor.observe(T0 + 11) is None and sensor.last_outcome == "saturated_frame"
    assert est.images == []
    folder2 = tmp_path / "g"
    folder2.mkdir()
    bgr = np.zeros((48, 64, 3), np.uint8)
    bgr[..., 1] = 120
    cv2.imwrite(str(folder2 / (format_name_time(T0) + ".png")), bgr)
    sensor = CameraSunSensor(FolderFrameSource(folder2), est)
    sensor.observe(T0 + 1)
    assert est.images[-1].ndim == 2 and est.images[-1].dtype == np.uint8  # colour -> grey
    assert sensor.last_outcome == "no_glint"
    sensor.observe(T0 + 2)  # nothing newer: the same frame is not measured twice
    assert sensor.last_outcome == "same frame" and len(est.images) == 1
    assert sensor.observe(T0 + 1000) is None and sensor.last_outcome == "no frame"  # too old
    assert dict(sensor.outcomes) == {"no_glint": 1, "same frame": 1, "no frame": 1}


def test_two_frames_of_one_time_are_named_once(tmp_path, caplog):
    """An audit's case: a camera's name and the canonical one for the same moment; one was
    taken by name order without a word."""
    folder = tmp_path / "f"
    _png(folder, T0, 10)
    cv2.imwrite(str(folder / "cam_2026-03-20_10-15-00.png"), np.full((4, 4), 20, np.uint8))
    src = FolderFrameSource(folder)
    assert src.grab(T0 + 1).time == T0
    src.grab(T0 + 2)
    assert caplog.text.count("name the same time") == 1
    assert f"{format_name_time(T0)}.png" in caplog.text and "cam_2026-03-20_10-15-00.png" in caplog.text
