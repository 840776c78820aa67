"""A batch of frames read as one sequence, each by a camera that has learned from other frames.

The default pipeline learns its camera as it runs: where between the rim's fix and the
rings' its sun lies (:mod:`.locator`), its rims' blend (:mod:`.blend`), the site when the
bundle has none (:mod:`.selfsite`).  A frame early in a sequence is read by a camera that
has learned little: halfway between the two fixes, 0.1 deg at most from the rim, where the
camera's answer can be 0.2 deg from either (docs/fisheye.md, step 10).  Online that is the
price of the first frames; offline, with the whole batch at hand, it need not be paid, and
no frame's own fixes need set its answer either: the frames of the second half are read in
order after the first (a camera that has seen the first half, as online), and those of the
first half by a second camera that has read the second half first (cross-fitting, as a
statistician splits a sample so that no point is fitted to itself).  The gates of the
sequence (the paper's rule 3) start afresh for the first half, as they do at the batch's
start.  Each frame of a batch of two or more is read twice.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from typing import TypeVar

from .pipeline import FramePipeline
from .result import FisheyeResult

#: the quality flag of a fix read by the camera that had read the batch's second half first
LEARNED_FROM_LATER = "learned_from_later_frames"

F = TypeVar("F")


def estimate_batch(
    make: Callable[[], FramePipeline],
    frames: Sequence[F],
    measure: Callable[[FramePipeline, F], FisheyeResult],
    forward: FramePipeline | None = None,
) -> list[FisheyeResult]:
    """Each of ``frames`` (in time order, one sequence) measured by ``measure(estimator,
    frame)``, the estimators made by ``make`` (a fresh camera each: the same bundle and
    options), so that no frame is read by a camera that learned from it.  ``forward``: the
    camera that reads them all in order (made by ``make`` when None), which has then seen
    the whole batch.

    The second half's frames (from ``len(frames) // 2`` on) are read by one camera after the
    first half's; the first half's by another after the second half's, their found fixes
    flagged :data:`LEARNED_FROM_LATER`.  A single frame is read once, by a fresh camera.

    Returns
    -------
    list of FisheyeResult
        One per frame, in the order of ``frames``.
    """
    forward = make() if forward is None else forward
    out = [measure(forward, f) for f in frames]
    half = len(frames) // 2
    if half == 0:
        return out
    later_first = make()
    for f in frames[half:]:
        measure(later_first, f)
    later_first.reset_sequence()
    for i, f in enumerate(frames[:half]):
        r = measure(later_first, f)
        out[i] = replace(r, quality=(*r.quality, LEARNED_FROM_LATER)) if r.found else r
    return out
