"""Fuzzing the image readers (issue 13): arbitrary bytes, damaged PNG/JPEG files and headers
of every format OpenCV reads announcing absurd sizes give a reason, never an exception, and
never an image above the pixel limit."""

from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np
from hypothesis import example, given
from hypothesis import strategies as st

from controller.vision.imageio import header_size, load_grey, read_image

from .strategies import bounded, scratch_dir

_DIR = scratch_dir("heliotrack-fuzz-img-")
REASONS = {
    "file_not_found",
    "unreadable_file",
    "is_a_directory",
    "empty_file",
    "truncated_file",
    "image_too_large",
    "undecodable_image",
    "unsupported_image_format",
}
LIMIT = 40_000  # pixels: small, so that the limit itself is exercised


def _encoded(ext: str, shape: tuple[int, ...], dtype=np.uint8) -> bytes:
    rng = np.random.default_rng(0)
    img = rng.integers(0, 255, shape).astype(dtype)
    ok, buf = cv2.imencode(ext, img)
    assert ok
    return buf.tobytes()


SAMPLES = [
    _encoded(".png", (32, 32)),
    _encoded(".png", (16, 16, 3)),
    _encoded(".png", (8, 8, 4), np.uint16),
    _encoded(".jpg", (32, 32)),
    _encoded(".jpg", (16, 24, 3)),
    _encoded(".bmp", (8, 8, 3)),
    _encoded(".pgm", (8, 8)),
    _encoded(".tif", (8, 8)),
    _encoded(".tif", (8, 8, 3), np.int16),  # decodes; cvtColor used to raise on it
    _encoded(".tif", (4, 4, 3), np.float64),
]


def _chunk(kind: bytes, data: bytes) -> bytes:
    return struct.pack(">I", len(data)) + kind + data + struct.pack(">I", zlib.crc32(kind + data))


@st.composite
def png_headers(draw) -> bytes:
    w, h = draw(st.integers(0, 2**32 - 1)), draw(st.integers(0, 2**32 - 1))
    depth, color = draw(st.sampled_from([1, 2, 4, 8, 16, 3])), draw(st.sampled_from([0, 2, 3, 4, 6, 5]))
    ihdr = struct.pack(">IIBBBBB", w, h, depth, color, 0, 0, draw(st.integers(0, 1)))
    body = zlib.compress(draw(st.binary(max_size=64)))
    return b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", ihdr) + _chunk(b"IDAT", body) + _chunk(b"IEND", b"")


@st.composite
def jpeg_headers(draw) -> bytes:
    w, h = draw(st.integers(0, 65535)), draw(st.integers(0, 65535))
    ncomp = draw(st.sampled_from([1, 3, 4, 0, 255]))
    sof = draw(st.sampled_from([0xC0, 0xC1, 0xC2, 0xC3, 0xC9, 0xCF]))
    comps = b"".join(bytes([i + 1, 0x11, 0]) for i in range(min(ncomp, 4)))
    seg = struct.pack(">BHHB", 8, h, w, ncomp) + comps
    junk = draw(st.binary(max_size=40))
    return b"\xff\xd8" + bytes([0xFF, sof]) + struct.pack(">H", len(seg) + 2) + seg + junk + b"\xff\xd9"


@st.composite
def other_headers(draw) -> bytes:
    w, h = draw(st.integers(0, 200_000)), draw(st.integers(0, 200_000))
    tail = draw(st.binary(max_size=64))
    kind = draw(st.sampled_from(["pgm", "ppm", "pam", "pfm", "bmp", "tiff", "gif", "hdr", "ras", "webp"]))
    if kind in ("pgm", "ppm"):
        maxval = draw(st.sampled_from([1, 255, 65535, 0, 70000]))
        head = f"{'P5' if kind == 'pgm' else 'P6'}\n{w} {h}\n{maxval}\n".encode()
    elif kind == "pam":
        head = f"P7\nWIDTH {w}\nHEIGHT {h}\nDEPTH 3\nMAXVAL 255\nTUPLTYPE RGB\nENDHDR\n".encode()
    elif kind == "pfm":
        head = f"PF\n{w} {h}\n-1.0\n".encode()
    elif kind == "bmp":
        bpp = draw(st.sampled_from([1, 4, 8, 16, 24, 32]))
        head = b"BM" + struct.pack("<IHHI", 0, 0, 0, 54)
        head += struct.pack("<IiiHHIIiiII", 40, w, draw(st.sampled_from([h, -h])), 1, bpp, 0, 0, 0, 0, 0, 0)
    elif kind == "tiff":
        entries = [
            (256, 4, 1, w),
            (257, 4, 1, h),
            (258, 3, 1, 8),
            (259, 3, 1, 1),
            (262, 3, 1, 1),
            (273, 4, 1, 8),
        ]
        entries += [(277, 3, 1, 1), (278, 4, 1, h), (279, 4, 1, len(tail))]
        ifd = struct.pack("<H", len(entries)) + b"".join(struct.pack("<HHII", *e) for e in entries)
        head = b"II*\x00" + struct.pack("<I", 8 + len(tail)) + tail + ifd + b"\x00\x00\x00\x00"
        tail = b""
    elif kind == "gif":
        head = b"GIF89a" + struct.pack("<HHBBB", w % 65536, h % 65536, 0, 0, 0)
    elif kind == "hdr":
        head = f"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y {h} +X {w}\n".encode()
    elif kind == "ras":
        head = b"\x59\xa6\x6a\x95" + struct.pack(">IIIIIII", w, h, 8, len(tail), 1, 0, 0)
    else:
        head = b"RIFF" + struct.pack("<I", 30 + len(tail)) + b"WEBPVP8X" + struct.pack("<I", 10)
        head += b"\x00\x00\x00\x00" + (w % 2**24).to_bytes(3, "little") + (h % 2**24).to_bytes(3, "little")
    return head + tail


@st.composite
def damaged(draw) -> bytes:
    data = bytearray(draw(st.sampled_from(SAMPLES)))
    for _ in range(draw(st.integers(0, 4))):
        i = draw(st.integers(0, len(data) - 1))
        data[i] = draw(st.integers(0, 255))
    return bytes(data[: draw(st.integers(0, len(data)))])


def check(data: bytes) -> None:
    path = _DIR / "frame.img"
    path.write_bytes(data)
    assert header_size(data) is None or all(v >= 0 for v in header_size(data))
    img, reason = read_image(path, max_pixels=LIMIT)
    if img is None:
        assert reason in REASONS
    else:
        assert reason is None and img.shape[0] * img.shape[1] <= LIMIT
    grey, reason = load_grey(path, max_pixels=LIMIT)
    if grey is None:
        assert reason in REASONS
    else:
        assert reason is None and grey.dtype == np.uint8 and grey.ndim == 2
        assert grey.shape[0] * grey.shape[1] <= LIMIT


@bounded(150)
@given(st.binary(max_size=300))
@example(b"")
@example(b"\xff\xd8")
@example(b"\x89PNG\r\n\x1a\n")
def test_any_bytes(data):
    check(data)


@bounded(150)
@given(damaged())
def test_truncated_and_corrupted_files(data):
    check(data)


@bounded(150)
@given(st.one_of(png_headers(), jpeg_headers(), other_headers()))
def test_absurd_header_sizes(data):
    check(data)


def test_paths_that_are_not_files(tmp_path):
    assert read_image(tmp_path / "none.png") == (None, "file_not_found")
    assert read_image(tmp_path) == (None, "is_a_directory")  # a folder
    assert read_image(str(tmp_path / "a\x00b.png")) == (None, "unreadable_file")
