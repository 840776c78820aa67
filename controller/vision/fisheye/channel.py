"""The glare channel: the grey image the default pipeline measures the glare on.

The mean of each pixel's two darkest channels (the glare is white, the clear sky blue:
docs/fisheye.md, step 1), computed in frame-sized buffers that are kept from one frame to
the next (:class:`FrameBuffers`).
"""

from __future__ import annotations

import cv2
import numpy as np


class FrameBuffers:
    """Frame-sized uint8 buffers kept from one frame to the next, by name.

    A frame-sized array allocated afresh each frame costs a page fault for each of its 4 kB
    pages whenever the allocator has handed that memory back to the system in between
    (glibc trims its heap once more than twice the largest recent chunk lies free at its
    top): at 640 x 480 about 650 faults and 1.4 ms a frame, a quarter of the default
    pipeline's time, and 4500 faults and 9 ms at 1920 x 1080 (measured on frames read from
    disk; frames rendered in the same process had raised the trim threshold and hid it).
    Not shared between threads.
    """

    def __init__(self) -> None:
        self._buffers: dict[str, np.ndarray] = {}

    def get(self, name: str, shape: tuple[int, ...]) -> np.ndarray:
        """The buffer ``name`` of ``shape`` (its contents are whatever the last frame left)."""
        buf = self._buffers.get(name)
        if buf is None or buf.shape != shape:
            buf = self._buffers[name] = np.empty(shape, np.uint8)
        return buf


def glare_channel(img: np.ndarray, buffers: FrameBuffers | None = None) -> np.ndarray:
    """The mean of each pixel's two darkest channels (uint8, rounded half to even).

    The glare is white, so its core saturates every channel; the sky around it is coloured,
    and its brightest channel (blue, in a clear sky) clips first, which bends the rim's
    profile differently on each side.  Dropping the brightest channel keeps the rim clear of
    that; keeping two channels (rather than the darkest alone) halves the noise of JPEG's
    sub-sampled colour.  ``buffers``: the frame-sized arrays to work in (the result is one
    of them, overwritten by the next call); without them, fresh arrays.
    """
    shape = img.shape[:2]
    bufs = buffers or FrameBuffers()
    b, g, r = (bufs.get(k, shape) for k in ("b", "g", "r"))
    lo, hi, out = (bufs.get(k, shape) for k in ("lo", "hi", "grey"))
    cv2.split(img, [b, g, r])
    cv2.min(b, g, dst=lo)
    cv2.max(b, g, dst=hi)
    cv2.min(hi, r, dst=hi)
    cv2.max(lo, hi, dst=hi)  # the middle channel
    cv2.min(lo, r, dst=lo)  # the darkest
    return cv2.addWeighted(lo, 0.5, hi, 0.5, 0.0, dst=out)
