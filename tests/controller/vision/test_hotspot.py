import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.vision.hotspot import _knee, segment_fast, segment_seed


def _blob_image(rng, shape=(120, 140), blobs=((60, 70, 6.0, 400.0),), bg=12):
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]]
    img = np.full(shape, float(bg))
    for cy, cx, sig, peak in blobs:
        img += peak * np.exp(-((yy - cy) ** 2 + (xx - cx) ** 2) / (2 * sig**2))
    img += rng.normal(0, 2.0, shape)
    return np.clip(np.rint(img), 0, 255).astype(np.uint8)


def _disk_mask(shape=(120, 140), r=55):
    yy, xx = np.mgrid[0 : shape[0], 0 : shape[1]]
    return (((yy - 60) ** 2 + (xx - 70) ** 2) < r * r).astype(np.uint8)


def test_knee_is_the_end_of_the_plateau():
    curve = (
        [(255, 0)]
        + [(i, 50) for i in range(254, 240, -1)]
        + [(i, 50 + 40 * (241 - i)) for i in range(240, 127, -1)]
    )
    assert _knee(curve) in (241, 240)


def test_no_glint_when_the_maximum_is_not_in_the_top_ten_percent():
    rng = np.random.default_rng(0)
    img = _blob_image(rng, blobs=((60, 70, 5.0, 150.0),))
    seg = segment_fast(img, _disk_mask())
    assert not seg.found and seg.reason == "no_glint"
    assert segment_seed(img, _disk_mask()).reason == "no_glint"


def test_single_glint_is_found_at_its_place():
    rng = np.random.default_rng(1)
    img = _blob_image(rng, blobs=((50, 80, 4.0, 600.0),))
    seg = segment_fast(img, _disk_mask())
    assert seg.found and seg.n_candidates == 1
    ys, xs = np.nonzero(seg.mask)
    assert abs(ys.mean() - 50) < 0.5 and abs(xs.mean() - 80) < 0.5


@settings(max_examples=25, deadline=None)
@given(st.integers(0, 10_000), st.integers(1, 3), st.sampled_from(["pseudocode", "prose"]))
def test_fast_mask_identical_to_literal_algorithm(seed, nblobs, rule):
    rng = np.random.default_rng(seed)
    blobs = [
        (
            rng.uniform(15, 105),
            rng.uniform(15, 125),
            rng.uniform(1.5, 7),
            rng.choice([300.0, 600.0, rng.uniform(200, 900)]),
        )
        for _ in range(nblobs)
    ]
    img = _blob_image(rng, blobs=blobs)
    M = _disk_mask()
    a = segment_seed(img, M, end_rule=rule)
    b = segment_fast(img, M, end_rule=rule)
    assert a.found == b.found
    if a.found:
        assert a.i_opt == b.i_opt
        assert a.curve == b.curve
        assert np.array_equal(a.mask, b.mask)


def test_ties_between_equal_saturated_blobs_are_broken_identically():
    rng = np.random.default_rng(3)
    img = _blob_image(rng, blobs=((40, 50, 3.0, 2000.0), (80, 95, 3.0, 2000.0)))
    M = _disk_mask()
    a, b = segment_seed(img, M), segment_fast(img, M)
    assert a.n_candidates >= 2
    assert np.array_equal(a.mask, b.mask)
