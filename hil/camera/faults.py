"""Camera frame faults: what a failing camera, cable or capture driver hands the controller.

:func:`damage` turns a good frame into the faulty one of a kind; ``camera_missing`` has no
frame at all (the frame source returns none).
"""

from __future__ import annotations

import numpy as np

CAMERA_FAULTS = (
    "camera_black",
    "camera_saturated",
    "camera_truncated",
    "camera_wrong_size",
    "camera_missing",
)


def damage(kind: str, image: np.ndarray, rng: np.random.Generator) -> np.ndarray | None:
    """``image`` as a fault of ``kind`` delivers it (None: no frame).

    - black: every pixel 0 (lens cap, shutter stuck, night gain lost);
    - saturated: every pixel at the type's maximum (exposure stuck open);
    - truncated: the lower part of the frame lost in transfer, filled with mid-grey as a
      JPEG decoder fills a cut file;
    - wrong_size: a frame of another resolution (a camera reset to its default mode);
    - missing: no frame.
    """
    top = np.iinfo(image.dtype).max if np.issubdtype(image.dtype, np.integer) else 1.0
    match kind:
        case "camera_black":
            return np.zeros_like(image)
        case "camera_saturated":
            return np.full_like(image, top)
        case "camera_truncated":
            out = image.copy()
            cut = int(rng.integers(1, max(image.shape[0], 2)))
            out[cut:] = top // 2 if isinstance(top, int) else top / 2
            return out
        case "camera_wrong_size":
            h, w = image.shape[:2]
            nh, nw = max(h // 2, 1), max((w * 3) // 4, 1)
            rows = np.linspace(0, h - 1, nh).astype(int)
            cols = np.linspace(0, w - 1, nw).astype(int)
            return np.ascontiguousarray(image[rows][:, cols])
        case "camera_missing":
            return None
    raise ValueError(f"unknown camera fault {kind!r}; known: {', '.join(CAMERA_FAULTS)}")
