"""A camera whose glares keep landing off the sun by one angle: its mount has moved.

The fisheye's ephemeris gate refuses a glare more than a degree from where the sun must be
(the plant's site and the bundle's rotation).  A camera bumped or re-mounted since its
orientation was calibrated sees the sun there every clear frame, each frame is
``gate_rejected``, and the loop tracks on the ephemeris: safe, but without a word (a
bundle calibrated at another site had done the same; docs/fisheye.md, "The fisheye in the
loop").  What tells a moved camera from a bright cloud's edge is that its glares sit off the
sun by the same offset frame after frame (a rotation of the camera moves the whole sky),
while clouds' edges scatter; a wrong site or clock would look alike, and the sentence says
so.  :class:`MountWatch` reads each result's ``glare_offset_deg`` (the refused glare
nearest the sun, from where the sun must be: along the horizon towards larger azimuth and
up, deg; :meth:`controller.vision.fisheye.FisheyeEstimator.estimate_image`) and says so once.
"""

from __future__ import annotations

import math
from collections import deque
from typing import Any

import numpy as np

#: glares refused this many times in a row (no sun found between), over at least SPAN_S (s),
#: whose offsets lie within MAX_SPREAD_DEG (deg, their median distance from their median);
#: one refusal is kept every STEP_S (s) at most, for twice SPAN_S, whatever the frame rate
MIN_FRAMES, SPAN_S, MAX_SPREAD_DEG, STEP_S = 12, 1800.0, 0.3, 10.0


class MountWatch:
    """Watches one camera's refusals for a moved mount (the module's docstring)."""

    def __init__(
        self, min_frames: int = MIN_FRAMES, span_s: float = SPAN_S, max_spread_deg: float = MAX_SPREAD_DEG
    ):
        self.min_frames, self.span_s, self.max_spread = int(min_frames), float(span_s), float(max_spread_deg)
        self._offsets: deque[tuple[float, float, float]] = deque()
        self.moved: tuple[float, float] | None = None  # the offset said, until the sun is found again

    def observe(self, t: float, result: Any) -> str | None:
        """Count the estimator's ``result`` of the frame at POSIX ``t``; a sentence to log when
        the camera's mount has just been judged moved, or found right again, else None."""
        if getattr(result, "found", False):
            self._offsets.clear()
            if self.moved is not None:
                self.moved = None
                return "the sun is found within its gates again"
            return None
        off = (getattr(result, "extra", None) or {}).get("glare_offset_deg")
        if getattr(result, "reason", None) != "gate_rejected" or off is None:
            return None  # no glare seen (a cloud, the night): says nothing of the mount
        if self._offsets and float(t) - self._offsets[-1][0] < STEP_S:
            return None  # a fast camera: its refusals are not counted more often than this
        self._offsets.append((float(t), float(off[0]), float(off[1])))
        while float(t) - self._offsets[0][0] > 2.0 * self.span_s:
            self._offsets.popleft()
        if self.moved is not None or len(self._offsets) < self.min_frames:
            return None
        ts = [o[0] for o in self._offsets]
        if ts[-1] - ts[0] < self.span_s:
            return None
        xy = np.array([(o[1], o[2]) for o in self._offsets])
        med = one_offset(xy, self.max_spread)
        if med is None:
            return None  # glares all over the sky: clouds' edges, not the camera
        self.moved = med
        return (
            f"its glares of the last {(ts[-1] - ts[0]) / 60:.0f} min ({len(xy)} frames) were all refused "
            f"{math.hypot(*self.moved):.2f} deg from where the sun must be, by the same offset "
            f"({self.moved[0]:+.2f} deg along the horizon, {self.moved[1]:+.2f} up): the camera has "
            "likely moved on its mount since its orientation was calibrated (heliotrack calibrate "
            "fisheye orientation), unless the plant's site or clock is off; the loop tracks "
            "without it meanwhile"
        )


def one_offset(offsets: np.ndarray, max_spread_deg: float = MAX_SPREAD_DEG) -> tuple[float, float] | None:
    """The median of ``offsets`` (n x 2, deg: along the horizon, up) when they lie about it
    within ``max_spread_deg`` (their median distance from it), else None: one offset, as a
    camera turned on its mount gives, not the scatter of clouds' edges."""
    med = np.median(offsets, axis=0)
    if float(np.median(np.hypot(*(offsets - med).T))) > max_spread_deg:
        return None
    return float(med[0]), float(med[1])
