"""The coarse blob search: every saturated speck marks its block, at any frame size."""

import cv2
import numpy as np
import pytest

from controller.vision.fisheye.blobs import find_blobs


@pytest.mark.parametrize("shape", [(480, 640), (960, 1280), (1080, 1920), (479, 641)])
def test_every_saturated_speck_and_the_glare_are_found_in_their_boxes(shape):
    H, W = shape
    grey = np.full(shape, 60, np.uint8)
    cv2.circle(grey, (W // 3, H // 2), H // 12, 255, -1)  # the glare
    rng = np.random.default_rng(H + W)
    specks = []
    for _ in range(12):  # 2 x 2 specks, anywhere against the blocks' edges
        x, y = int(rng.integers(W // 2, W - 3)), int(rng.integers(2, H - 3))
        if any(abs(x - u) < 40 and abs(y - v) < 40 for u, v in specks):
            continue
        grey[y : y + 2, x : x + 2] = 255
        specks.append((x, y))
    blobs = find_blobs(grey, 250.0, None, max_blobs=50)
    assert len(blobs) == len(specks) + 1
    assert blobs[0].area_px == int((grey == 255).sum()) - 4 * len(specks)  # largest first
    for x, y in specks:
        inside = [
            b
            for b in blobs
            if b.bbox[0] <= x
            and x + 2 <= b.bbox[0] + b.bbox[2]
            and b.bbox[1] <= y
            and y + 2 <= b.bbox[1] + b.bbox[3]
        ]
        assert len(inside) == 1 and inside[0].area_px == 4


def test_a_mask_keeps_out_what_it_covers():
    grey = np.full((480, 640), 60, np.uint8)
    grey[100:104, 100:104] = 255
    grey[300:304, 500:504] = 255
    valid = np.full(grey.shape, 255, np.uint8)
    valid[:, 400:] = 0
    blobs = find_blobs(grey, 250.0, valid)
    assert len(blobs) == 1 and blobs[0].bbox[0] <= 100 < blobs[0].bbox[0] + blobs[0].bbox[2]
    assert blobs[0].area_px == 16
