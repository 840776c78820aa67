"""What every fisheye pipeline does before its own steps: read the file, check the frame."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from .frames import as_bgr8, load_frame
from .result import FisheyeResult, not_found


class FramePipeline:
    """Base of the fisheye estimators: a file or an in-memory frame becomes a checked BGR
    frame of the bundle's size, or a not-found result with the reason.

    Subclasses set ``algorithm``, ``frame`` ("enu" or "model") and ``shape`` (rows,
    columns) and implement :meth:`estimate_image` and :meth:`reset_sequence`.
    """

    algorithm: str
    frame: str
    shape: tuple[int, int]

    def estimate_image(self, image, t: float | None = None, prior=None) -> FisheyeResult:
        raise NotImplementedError

    def reset_sequence(self) -> None:
        """Start another sequence: the next frame is not gated by the last one's detection."""
        raise NotImplementedError

    def estimate_file(self, path: str | Path, t: float | None = None, prior=None) -> FisheyeResult:
        img, reason = load_frame(path)
        if img is None:
            return not_found(str(path), reason or "unreadable_file", t, self.frame, self.algorithm)
        res = self.estimate_image(img, t, prior)
        res.image = str(path)
        return res

    def checked_frame(self, image, t: float | None) -> tuple[np.ndarray | None, FisheyeResult | None]:
        """(BGR uint8 frame, None), or (None, the not-found result: no image, wrong size)."""
        img, reason = as_bgr8(image)
        if img is None:
            return None, not_found(None, reason or "no_image", t, self.frame, self.algorithm)
        if img.shape[:2] != self.shape:
            return None, not_found(
                None,
                "size_mismatch",
                t,
                self.frame,
                self.algorithm,
                expected_shape=list(self.shape),
                got_shape=list(img.shape[:2]),
            )
        return img, None
