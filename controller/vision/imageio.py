"""Reading frames defensively: a truncated, oversized or unreadable file is a reason, never
an exception, and the pixel count is checked from the header before anything is decoded."""

from __future__ import annotations

import struct
from pathlib import Path

import cv2
import numpy as np

#: Larger images are refused before decoding (a 20000 x 20000 PNG would take 1.2 GB).
MAX_PIXELS = 50_000_000

_PNG = b"\x89PNG\r\n\x1a\n"
_JPEG = b"\xff\xd8"
# JPEG start-of-frame markers (baseline, progressive, lossless...), not DHT/JPG/DAC
_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def header_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG or JPEG header without decoding; None for other formats
    or when the header cannot be read."""
    if data[:8] == _PNG and len(data) >= 24 and data[12:16] == b"IHDR":
        w, h = struct.unpack(">II", data[16:24])
        return int(w), int(h)
    if data[:2] == _JPEG:
        i = 2
        while i + 9 <= len(data):
            if data[i] != 0xFF:
                return None
            marker = data[i + 1]
            if marker in (0xD8, 0x01) or 0xD0 <= marker <= 0xD7:
                i += 2
                continue
            length = struct.unpack(">H", data[i + 2 : i + 4])[0]
            if marker in _SOF:
                h, w = struct.unpack(">HH", data[i + 5 : i + 9])
                return int(w), int(h)
            i += 2 + length
    return None


def read_image(path: str | Path, *, max_pixels: int = MAX_PIXELS) -> tuple[np.ndarray | None, str | None]:
    """The image as OpenCV decodes it (8 or 16 bit, grey or BGR/BGRA), or (None, reason).

    JPEG must end with its EOI marker and PNG with its IEND chunk: OpenCV otherwise decodes
    a truncated file into a partly grey frame.  Reasons: ``file_not_found``,
    ``is_a_directory``, ``unreadable_file``, ``empty_file``, ``truncated_file``, ``image_too_large``,
    ``undecodable_image``.
    """
    p = Path(path)
    try:
        data = p.read_bytes()
    except FileNotFoundError:
        return None, "file_not_found"
    except IsADirectoryError:  # a folder given where its images were meant
        return None, "is_a_directory"
    except (OSError, ValueError):  # no permission; a NUL in the name
        return None, "unreadable_file"
    if len(data) == 0:
        return None, "empty_file"
    if data[:2] == _JPEG:
        if not data.rstrip(b"\x00\r\n ").endswith(b"\xff\xd9"):
            return None, "truncated_file"
    elif data[:8] == _PNG:
        if b"IEND" not in data[-16:]:
            return None, "truncated_file"
    size = header_size(data)
    if size is not None and size[0] * size[1] > max_pixels:
        return None, "image_too_large"
    arr = np.frombuffer(data, np.uint8)
    try:
        img = cv2.imdecode(arr, cv2.IMREAD_UNCHANGED)
    except cv2.error:
        img = None
    if img is None:
        return None, "undecodable_image"
    if img.size > max_pixels * (img.shape[2] if img.ndim == 3 else 1):
        return None, "image_too_large"
    return img, None


def load_grey(path: str | Path, *, max_pixels: int = MAX_PIXELS) -> tuple[np.ndarray | None, str | None]:
    """8-bit grey image, or (None, reason) (see :func:`read_image`; also
    ``unsupported_image_format``)."""
    img, reason = read_image(path, max_pixels=max_pixels)
    if img is None:
        return None, reason
    # 8 or 16 bit, grey, BGR or BGRA only: a TIFF of signed or 64-bit samples, or with two
    # or five channels, decodes but cv2.cvtColor raises on it
    if img.dtype not in (np.uint8, np.uint16) or img.ndim == 3 and img.shape[2] not in (3, 4):
        return None, "unsupported_image_format"
    if img.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        img = cv2.cvtColor(img, code)
    if img.dtype == np.uint16:
        img = (img.astype(np.uint16) >> 8).astype(np.uint8)
    if img.dtype != np.uint8 or img.ndim != 2:
        return None, "unsupported_image_format"
    return np.ascontiguousarray(img), None
