"""Reading frames defensively: a truncated or unreadable file is a reason, never an exception."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np


def load_grey(path: str | Path) -> tuple[np.ndarray | None, str | None]:
    """8-bit grey image, or (None, reason).  JPEG must end with its EOI marker and PNG with
    its IEND chunk: OpenCV otherwise decodes a truncated file into a partly grey frame."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        return None, "file_not_found"
    except OSError:
        return None, "unreadable_file"
    if len(data) == 0:
        return None, "empty_file"
    if data[:2] == b"\xff\xd8":
        if not data.rstrip(b"\x00\r\n ").endswith(b"\xff\xd9"):
            return None, "truncated_file"
    elif data[:8] == b"\x89PNG\r\n\x1a\n":
        if b"IEND" not in data[-16:]:
            return None, "truncated_file"
    arr = np.frombuffer(data, np.uint8)
    try:
        img = cv2.imdecode(arr, cv2.IMREAD_UNCHANGED)
    except cv2.error:
        img = None
    if img is None:
        return None, "undecodable_image"
    if img.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        img = cv2.cvtColor(img, code)
    if img.dtype == np.uint16:
        img = (img >> 8).astype(np.uint8)
    if img.dtype != np.uint8 or img.ndim != 2:
        return None, "unsupported_image_format"
    return np.ascontiguousarray(img), None
