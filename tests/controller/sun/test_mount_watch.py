"""A camera whose glares keep landing off the sun by one angle (controller.sun.mount_watch)."""

from types import SimpleNamespace

import numpy as np

from controller.sun.mount_watch import MountWatch


def refused(off):
    return SimpleNamespace(found=False, reason="gate_rejected", extra={"glare_offset_deg": list(off)})


FOUND = SimpleNamespace(found=True, reason=None, extra={})


def test_one_offset_frame_after_frame_for_half_an_hour_is_said_once_and_unsaid_when_found():
    w = MountWatch()
    rng = np.random.default_rng(3)
    said = [
        w.observe(150.0 * k, refused((1.4 + rng.normal(0, 0.05), -0.3 + rng.normal(0, 0.05))))
        for k in range(20)
    ]
    first = [k for k, s in enumerate(said) if s]
    assert first == [12]  # the 13th frame: 12 frames spanning 30 min
    assert "by the same offset" in said[12] and "heliotrack calibrate fisheye orientation" in said[12]
    assert w.moved is not None and abs(w.moved[0] - 1.4) < 0.1 and abs(w.moved[1] + 0.3) < 0.1
    assert w.observe(3000.0, FOUND) == "the sun is found within its gates again"
    assert w.moved is None and w.observe(3150.0, FOUND) is None


def test_glares_scattered_over_the_sky_are_clouds_not_a_moved_camera():
    w = MountWatch()
    rng = np.random.default_rng(5)
    assert not any(w.observe(150.0 * k, refused(rng.uniform(-4, 4, 2))) for k in range(40))
    assert w.moved is None


def test_too_few_or_too_short_or_broken_by_a_sun_found_says_nothing():
    w = MountWatch()
    assert not any(w.observe(60.0 * k, refused((1.5, 0.0))) for k in range(20))  # 19 min only
    w = MountWatch()
    for k in range(30):
        res = FOUND if k % 10 == 9 else refused((1.5, 0.0))
        assert w.observe(150.0 * k, res) is None  # a sun found every 10 frames: the mount is right


def test_a_fast_camera_is_judged_over_the_same_half_hour():
    w = MountWatch()
    said = [w.observe(1.0 * k, refused((0.0, -1.3))) for k in range(3600)]  # a frame a second
    assert [k for k, s in enumerate(said) if s] == [1800]
    assert "the last 30 min (181 frames)" in said[1800]


def test_frames_without_a_glare_neither_count_nor_reset():
    w = MountWatch()
    dark = SimpleNamespace(found=False, reason="no_sun_glare", extra={})
    said = []
    for k in range(24):
        said.append(w.observe(150.0 * k, refused((-1.2, 0.4)) if k % 2 == 0 else dark))
    assert [k for k, s in enumerate(said) if s] == [22]  # the 12th refusal, 55 min after the first
