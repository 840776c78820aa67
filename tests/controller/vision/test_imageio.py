"""The one image reader: reasons, never exceptions; sizes checked before decoding."""

import struct
import zlib

import cv2
import numpy as np
import pytest

from controller.vision.imageio import header_size, load_grey, read_image


def _png_header_only(w: int, h: int) -> bytes:
    ihdr = struct.pack(">IIBBBBB", w, h, 8, 0, 0, 0, 0)
    chunk = b"IHDR" + ihdr
    return (
        b"\x89PNG\r\n\x1a\n"
        + struct.pack(">I", len(ihdr))
        + chunk
        + struct.pack(">I", zlib.crc32(chunk))
        + b"\x00\x00\x00\x00IEND\xaeB`\x82"
    )


def test_sizes_from_the_header(tmp_path):
    img = np.zeros((30, 40, 3), np.uint8)
    for ext in (".png", ".jpg"):
        ok, buf = cv2.imencode(ext, img)
        assert header_size(buf.tobytes()) == (40, 30)


def test_a_huge_image_is_refused_before_decoding(tmp_path):
    p = tmp_path / "huge.png"
    p.write_bytes(_png_header_only(20000, 20000))
    assert read_image(p) == (None, "image_too_large")


@pytest.mark.parametrize(
    "content, reason",
    [
        (b"", "empty_file"),
        (b"not an image at all", "undecodable_image"),
        (b"\xff\xd8\xff\xe0 garbage", "truncated_file"),
    ],
)
def test_bad_files_give_reasons(tmp_path, content, reason):
    p = tmp_path / "x.jpg"
    p.write_bytes(content)
    assert load_grey(p) == (None, reason)
    assert load_grey(tmp_path / "missing.png") == (None, "file_not_found")


def test_colour_is_kept_by_read_image_and_greyed_by_load_grey(tmp_path):
    p = tmp_path / "c.png"
    cv2.imwrite(str(p), np.dstack([np.full((5, 7), v, np.uint8) for v in (10, 20, 30)]))
    img, _ = read_image(p)
    grey, _ = load_grey(p)
    assert img.shape == (5, 7, 3) and grey.shape == (5, 7) and grey.dtype == np.uint8
