"""Frames read as ``heliotrack estimate`` reads the frames of one call: a fresh camera a call,
as a batch (:func:`controller.vision.fisheye.batch.estimate_batch`) and with ``--causal``.
The benches' own passes keep one camera across days, as ``heliotrack run`` does."""

from __future__ import annotations

from typing import Any


class CallReadings:
    """Each call's frames read both ways by fresh cameras of each bundle; ``records``:
    ``"batch"`` or ``"causal"`` plus the bundle's key -> [(result, az_deg, el_deg), ...]."""

    def __init__(self, bundles: dict[str, Any]):
        self.bundles = bundles
        self.records: dict[str, list] = {f"{m}{k}": [] for m in ("batch", "causal") for k in bundles}

    def add_call(self, frames: list[tuple[float, Any, float, float]]) -> None:
        """One call's ``frames``: (POSIX s, BGR image, sun az deg, sun el deg), in time order."""
        from controller.vision.fisheye import FisheyeEstimator
        from controller.vision.fisheye.batch import estimate_batch

        for k, b in self.bundles.items():
            causal = FisheyeEstimator(b)
            self.records[f"causal{k}"] += [
                (causal.estimate_image(img, t), az, el) for t, img, az, el in frames
            ]
            batch = estimate_batch(
                lambda b=b: FisheyeEstimator(b), frames, lambda e, f: e.estimate_image(f[1], f[0])
            )
            self.records[f"batch{k}"] += [(r, az, el) for r, (_, _, az, el) in zip(batch, frames)]
