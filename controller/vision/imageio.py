"""Reading frames defensively: a truncated or unreadable file is a reason, never an exception."""

from __future__ import annotations

import re
from datetime import datetime, timezone
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


_TS = re.compile(
    r"(\d{4})-?(\d{2})-?(\d{2})[T_ -]?(\d{2})[:\-]?(\d{2})[:\-]?(\d{2})(?:[.,](\d+))?"
    r"(Z|[+-]\d{2}:?\d{2})?")


def time_from_name(name: str) -> float | None:
    """POSIX seconds from an ISO-like timestamp in ``name`` (UTC unless an offset is given)."""
    m = _TS.search(Path(name).name)
    if not m:
        return None
    y, mo, d, h, mi, s, frac, tz = m.groups()
    try:
        dt = datetime(int(y), int(mo), int(d), int(h), int(mi), int(s), tzinfo=timezone.utc)
    except ValueError:
        return None
    t = dt.timestamp() + (float("0." + frac) if frac else 0.0)
    if tz and tz != "Z":
        sign = 1 if tz[0] == "+" else -1
        hh, mm = int(tz[1:3]), int(tz[-2:])
        t -= sign * (hh * 3600 + mm * 60)
    return t
