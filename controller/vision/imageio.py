"""Reading frames defensively: a truncated, oversized or unreadable file is a reason, never
an exception, and the pixel count is checked from the header before anything is decoded."""

from __future__ import annotations

import re
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
# Radiance RGBE: "#?RADIANCE" (or "#?RGBE"), header lines, a blank line, then the
# resolution line, e.g. "-Y 480 +X 640" (rows first) or "+X 640 -Y 480"
_RGBE = (b"#?RADIANCE", b"#?RGBE")
_RGBE_SIZE = re.compile(rb"\n\n([-+][XY]) +(\d{1,12}) +([-+][XY]) +(\d{1,12})\r?\n")


def header_size(data: bytes) -> tuple[int, int] | None:
    """(width, height) from a PNG, JPEG or Radiance (HDR) header without decoding; None
    for other formats or when the header cannot be read.

    OpenCV decodes a Radiance buffer through a temporary file, which it leaves behind in
    the temporary folder when the header's size makes it throw (over 2**30 pixels): such a
    frame must be refused before :func:`cv2.imdecode` sees it."""
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
    if data.startswith(_RGBE):
        m = _RGBE_SIZE.search(data, 0, 64 * 1024)
        if m is not None and m.group(1)[1:] != m.group(3)[1:]:
            a, b = int(m.group(2)), int(m.group(4))
            return (b, a) if m.group(1).endswith(b"Y") else (a, b)
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


#: The full scales of the 8-, 10-, 12- and 14-bit sensors whose frames come in 16-bit files
#: (machine-vision PNG and TIFF): a frame whose brightest pixel is exactly one of them is
#: taken as that sensor's, the sun (or its glint) saturating it.  Other 16-bit frames keep
#: their top byte.
SENSOR_FULL_SCALES = (255, 1023, 4095, 16383)


def to_uint8(img: np.ndarray) -> tuple[np.ndarray | None, str | None]:
    """The image's samples as 8 bits, or (None, reason).

    16-bit: the top byte, or scaled from a smaller sensor's full scale (``SENSOR_FULL_SCALES``;
    a 12-bit PNG had read as a black frame); float: 0..1 when its maximum is at most 2 (a
    pixel a hair over 1 after a denoiser), else 0..255, and ``unsupported_image_format``
    over 256 (linear HDR, whose exposure is not known here), ``non_finite_pixels`` for a NaN
    or an infinity; any other sample type ``unsupported_image_format``."""
    if img.dtype == np.uint8:
        return img, None
    if img.dtype == np.uint16:
        full = int(img.max()) if img.size else 0
        if full in SENSOR_FULL_SCALES:
            return cv2.convertScaleAbs(img, alpha=255.0 / full), None
        return (img >> 8).astype(np.uint8), None
    if img.dtype in (np.float32, np.float64):
        if not np.all(np.isfinite(img)):
            return None, "non_finite_pixels"
        top = float(img.max()) if img.size else 0.0
        if top > 256.0:
            return None, "unsupported_image_format"
        scale = 255.0 if top <= 2.0 else 1.0
        return np.clip(np.rint(img * scale), 0, 255).astype(np.uint8), None
    return None, "unsupported_image_format"


def load_grey(path: str | Path, *, max_pixels: int = MAX_PIXELS) -> tuple[np.ndarray | None, str | None]:
    """8-bit grey image, or (None, reason) (see :func:`read_image`; also
    ``unsupported_image_format``)."""
    img, reason = read_image(path, max_pixels=max_pixels)
    if img is None:
        return None, reason
    # grey, BGR or BGRA only: a TIFF with two or five channels decodes but cv2.cvtColor
    # raises on it; signed or 64-bit integer samples are refused by to_uint8
    if img.ndim == 3 and img.shape[2] not in (3, 4):
        return None, "unsupported_image_format"
    img, why = to_uint8(img)
    if img is None:
        return None, why
    if img.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if img.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        img = cv2.cvtColor(img, code)
    if img.ndim != 2:
        return None, "unsupported_image_format"
    return np.ascontiguousarray(img), None
