"""A batch read as one sequence (controller.vision.fisheye.batch), on the third renderer's
frames: a sky that is a product, whose rim reads a low sun 0.07-0.08 deg off where the
rings read it right, so that a camera that has learned nothing (halfway) is measurably off."""

import numpy as np
import pytest

from benchmarks import fisheye_third as ft
from benchmarks.fisheye_suites import angle_deg
from controller.calibration.fisheye_bundle import fisheye_bundle_from_dict
from controller.sun.types import azel_to_enu
from controller.vision.fisheye import FisheyeEstimator
from controller.vision.fisheye.batch import LEARNED_FROM_LATER, estimate_batch


@pytest.fixture(scope="module")
def day():
    """The third renderer's Mar 20, a frame an hour (11 frames, the sun 10-56 deg), and a
    maker of fresh cameras for its bundle (no ``locator`` choice: they start halfway)."""
    look = ft.LOOKS[0]
    scene = ft.ThirdScene(look)
    frames = []
    for t, az, el in ft.sun_frames(ft.DAYS[0], 60):
        rng = np.random.default_rng([look.width, look.height, int(t)])
        frames.append((t, scene.render(ft.sun_enu(az, el), rng), ft.sun_enu(az, el)))
    bundle = fisheye_bundle_from_dict(ft.bundle_dict(look))
    assert bundle.orientation is None or bundle.orientation.locator is None
    return frames, lambda: FisheyeEstimator(bundle)


def _measure(est, f):
    return est.estimate_image(f[1], f[0])


def _errors(results, frames):
    return [
        angle_deg(azel_to_enu(r.az_deg, r.el_deg), f[2]) if r.found else None for r, f in zip(results, frames)
    ]


def test_the_first_frames_are_read_by_a_camera_that_has_learned_from_the_later_ones(day):
    frames, make = day
    est = make()
    causal = _errors([_measure(est, f) for f in frames], frames)
    batch = estimate_batch(make, frames, _measure)
    got = _errors(batch, frames)
    # read cold, the morning's first two suns lie halfway between the rim and the rings
    assert causal[0] > 0.05 and causal[1] > 0.05, causal
    assert got[0] < 0.02 and got[1] < 0.02, got
    half = len(frames) // 2
    assert all(LEARNED_FROM_LATER in r.quality for r in batch[:half] if r.found)
    assert not any(LEARNED_FROM_LATER in r.quality for r in batch[half:])
    # the second half is read as it comes, by a camera that has seen the first half
    assert got[half:] == causal[half:]


def test_no_frame_is_read_by_a_camera_that_has_learned_from_it(day):
    frames, make = day
    reads: list[tuple[int, int]] = []  # (camera, frame index) in the order read
    cameras: list[FisheyeEstimator] = []

    def make_logged():
        cameras.append(make())
        return cameras[-1]

    def measure(est, f):
        reads.append((cameras.index(est), next(i for i, g in enumerate(frames) if g is f)))
        return _measure(est, f)

    out = estimate_batch(make_logged, frames, measure)
    n, half = len(frames), len(frames) // 2
    assert len(out) == n and len(cameras) == 2
    assert [i for c, i in reads if c == 0] == list(range(n))
    assert [i for c, i in reads if c == 1] == [*range(half, n), *range(half)]


def test_one_frame_is_read_once_by_a_fresh_camera(day):
    frames, make = day
    made: list[FisheyeEstimator] = []

    def make_counted():
        made.append(make())
        return made[-1]

    (r,) = estimate_batch(make_counted, frames[:1], _measure)
    assert len(made) == 1 and LEARNED_FROM_LATER not in r.quality
    assert _errors([r], frames[:1]) == _errors([_measure(make(), frames[0])], frames[:1])
