"""The glare channel (:mod:`controller.vision.fisheye.channel`)."""

import numpy as np

from controller.vision.fisheye.channel import FrameBuffers, glare_channel


def test_glare_channel_drops_each_pixels_brightest_channel():
    img = np.array([[[255, 100, 50], [10, 20, 30], [255, 255, 255]]], np.uint8)
    assert glare_channel(img).tolist() == [[75, 15, 255]]


def test_glare_channel_is_the_two_darkest_channels_mean_rounded_half_to_even_in_reused_buffers():
    rng = np.random.default_rng(3)
    imgs = [rng.integers(0, 256, (37, 53, 3), dtype=np.uint8) for _ in range(3)]
    bufs = FrameBuffers()
    for img in imgs:
        two = np.sort(img.astype(np.int64), axis=2)[:, :, :2].sum(axis=2)
        expected = (two // 2 + (two % 2) * ((two // 2) % 2)).astype(np.uint8)  # x.5 to even
        assert np.array_equal(glare_channel(img, bufs), expected)
        assert np.array_equal(glare_channel(img), expected)
