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
    ok, buf = cv2.imencode(".hdr", img.astype(np.float32))
    assert header_size(buf.tobytes()) == (40, 30)
    assert header_size(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n+X 7 -Y 5\n") == (7, 5)


def test_a_huge_radiance_header_leaves_no_temporary_file(tmp_path, monkeypatch):
    # OpenCV decodes RGBE buffers through a temporary file and left it behind when the
    # header's size made it throw: one file in /tmp per such frame, for good
    temp = tmp_path / "opencv-temp"
    temp.mkdir()
    monkeypatch.setenv("OPENCV_TEMP_PATH", str(temp))
    p = tmp_path / "huge.hdr"
    p.write_bytes(b"#?RADIANCE\nFORMAT=32-bit_rle_rgbe\n\n-Y 134716 +X 134716\n" + bytes(16))
    assert read_image(p) == (None, "image_too_large")
    assert list(temp.iterdir()) == []


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


@pytest.mark.parametrize(
    "write, want",
    [
        (lambda im: im.astype(np.uint16) * 257, 1),  # 16-bit: the top byte
        (lambda im: np.rint(im * (4095 / 255)).astype(np.uint16), 1),  # a 12-bit sensor's
        (lambda im: im.astype(np.float32) / 255.0, 1),  # float 0..1
    ],
)
def test_other_depths_read_as_the_8_bit_frame(tmp_path, write, want):
    """The hotspot's reader had kept a 16-bit file's top byte only (a 12-bit camera's glint
    read at 15 of 255) and refused float frames."""
    img = np.zeros((20, 30), np.uint8)
    img[8:12, 10:14] = 255  # a saturated glint
    img[0, :] = 40
    p = tmp_path / "f.tif"
    assert cv2.imwrite(str(p), write(img))
    grey, reason = load_grey(p)
    assert reason is None and np.abs(grey.astype(int) - img).max() <= want


def test_the_loops_camera_reads_a_12_bit_frame_as_the_estimators_do():
    """The loop's camera path (grey8) had its own 16-bit rule: the top byte only."""
    from controller.sun.camera import grey8

    img = np.zeros((20, 30), np.uint16)
    img[8:12, 10:14] = 4095  # a 12-bit sensor's saturated glint
    got = grey8(np.dstack([img] * 3))
    assert got is not None and got.dtype == np.uint8 and got.max() == 255 and got.shape == (20, 30)
