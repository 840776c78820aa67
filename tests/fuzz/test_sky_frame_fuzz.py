"""Fuzzing the fisheye pipeline with synthetic sky frames (issue 14): flat skies with
saturated patches, bars and rings of any size, noise and JPEG.  Whatever the frame, the
default pipeline answers with a result (a reason when it finds no sun), never an
exception, and a result it calls found is finite."""

from __future__ import annotations

import math

import cv2
import numpy as np
from hypothesis import example, given
from hypothesis import strategies as st

from benchmarks import fisheye_other as other
from controller.vision.fisheye import FisheyeEstimator

from .strategies import bounded

W, H = other.SENSOR.width, other.SENSOR.height
EST = FisheyeEstimator(other.bundle(other.rotation()))

shapes = st.lists(
    st.tuples(
        st.sampled_from(["rect", "ellipse", "bar", "ring"]),
        st.integers(-20, W + 20),  # x
        st.integers(-20, H + 20),  # y
        st.integers(1, 90),  # size (px)
        st.floats(0.05, 1.0),  # aspect
        st.tuples(st.integers(200, 255), st.integers(200, 255), st.integers(200, 255)),
    ),
    min_size=1,
    max_size=3,
)


def frame(bg: int, items, sigma: float, seed: int, blur: float, quality: int) -> np.ndarray:
    img = np.full((H, W, 3), bg, np.uint8)
    for kind, x, y, size, aspect, colour in items:
        h = max(int(size * aspect), 1)
        if kind == "rect":
            img[max(y, 0) : max(y + h, 0), max(x, 0) : max(x + size, 0)] = colour
        elif kind == "ellipse":
            cv2.ellipse(img, (x, y), (size, h), 30.0, 0, 360, colour, -1)
        elif kind == "bar":
            cv2.line(img, (x, y), (x + size * 3, y + h), colour, max(h // 4, 1))
        else:
            cv2.circle(img, (x, y), size, colour, max(h // 8, 1))
    if blur > 0:
        img = cv2.GaussianBlur(img, (0, 0), blur)
    if sigma > 0:
        img = np.clip(img + np.random.default_rng(seed).normal(0.0, sigma, img.shape), 0, 255).astype(
            np.uint8
        )
    if quality:
        img = cv2.imdecode(
            cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, quality])[1], cv2.IMREAD_COLOR
        )
    return img


@bounded(60)
@given(
    bg=st.integers(0, 180),
    items=shapes,
    sigma=st.sampled_from([0.0, 1.0, 3.0]),
    seed=st.integers(0, 4),
    blur=st.sampled_from([0.0, 0.8, 3.0]),
    quality=st.sampled_from([0, 40, 85]),
)
# found by fuzzing with frames like these: a noisy flat rectangle whose rim a cone fitted 84 deg wide and the
# blend then inverted (radius -240 deg); the next pass had no samples to read and raised
@example(
    bg=75, items=[("rect", 155, 101, 57, 42 / 57, (211, 247, 243))], sigma=1.0, seed=0, blur=0.0, quality=0
)
@example(
    bg=29, items=[("rect", 386, 254, 48, 38 / 48, (227, 216, 243))], sigma=1.0, seed=4, blur=0.0, quality=0
)
def test_any_frame_gives_a_result_never_an_exception(bg, items, sigma, seed, blur, quality):
    EST.reset_sequence()
    res = EST.estimate_image(frame(bg, items, sigma, seed, blur, quality), None)
    if res.found:
        assert res.reason is None
        assert math.isfinite(res.az_deg) and math.isfinite(res.el_deg)
        assert res.sigma_deg is not None and 0.0 < res.sigma_deg < math.inf
    else:
        assert isinstance(res.reason, str) and res.reason
