"""A frame of noise is never a sun (issue 13: estimate on random noise said found, 162 deg
off, sigma 0.19 deg)."""

import numpy as np
import pytest

from controller.calibration import load_bundle
from controller.vision import HotspotEstimator
from tests.conftest import REPO


@pytest.fixture(scope="module")
def est():
    return HotspotEstimator(load_bundle(REPO / "config" / "calibration" / "recommended.toml"))


@pytest.mark.parametrize("kind", ["uniform", "bright", "salt"])
def test_noise_is_not_a_glint(est, kind):
    rng = np.random.default_rng(7)
    h, w = est.shape
    if kind == "uniform":
        img = rng.integers(0, 256, (h, w), dtype=np.uint8)
    elif kind == "bright":
        img = np.clip(rng.normal(200, 30, (h, w)), 0, 255).astype(np.uint8)
    else:  # dark frame sprinkled with hot pixels
        img = np.clip(rng.normal(20, 4, (h, w)), 0, 255).astype(np.uint8)
        idx = rng.integers(0, h * w, 400)
        img.flat[idx] = 255
    res = est.estimate_image(img, 1_710_928_800.0)
    assert not res.found, res.to_json()
    assert res.reason in ("ambiguous_bright_spots", "no_distinct_glint", "no_glint"), res.reason
