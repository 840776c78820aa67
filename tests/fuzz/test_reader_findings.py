"""What the data-file and image fuzzers found (issue 13), one regression test each."""

from __future__ import annotations

import cv2
import numpy as np
import pytest

from controller.errors import InputError
from controller.sky.io import read_csv_record
from controller.sunpath.io import read_observations
from controller.vision.imageio import load_grey, read_image


def test_a_first_row_longer_than_the_header_no_longer_shifts_the_columns(tmp_path):
    """pandas took the first field of such a row as an index: time 1000000000 became the
    index, GHI (1) became the time and the extra field (5) the GHI, silently."""
    path = tmp_path / "ghi.csv"
    path.write_text("time,ghi\n1000000000,1,5\n1000000060,2\n")
    with pytest.raises(InputError, match=r"row 2: more fields than the header"):
        read_csv_record(path)


@pytest.mark.parametrize("word", ["now", "today"])
def test_now_and_today_are_not_sample_times(tmp_path, word):
    """pandas reads them as the present moment: a record dated by the clock of the reader."""
    path = tmp_path / "ghi.csv"
    path.write_text(f"time,ghi\n2024-03-20T10:00:00Z,100\n{word},120\n")
    with pytest.raises(InputError, match=rf"row 3, column 'time': .*got '{word}'"):
        read_csv_record(path)


def test_an_observation_with_a_decimal_comma_is_refused(tmp_path):
    """csv.DictReader put the extra fields aside: "10,5" read as az 10, el 5."""
    path = tmp_path / "obs.csv"
    path.write_text("time,az_deg,el_deg\n2024-03-20T10:15:00Z,120,5,30,2\n")
    with pytest.raises(InputError, match=r"row 2: 5 fields, the header names 3 \(a decimal comma"):
        read_observations(path)


@pytest.mark.parametrize("dtype", [np.int8, np.int16, np.int32, np.float64])
def test_a_colour_tiff_of_samples_cv_cannot_convert_is_a_reason(tmp_path, dtype):
    """load_grey raised cv2.error ("Unsupported depth of input image") from cvtColor.  Float
    samples are read since (0..1 when at most 2), the signed integers stay refused."""
    ok, buf = cv2.imencode(".tif", np.ones((4, 4, 3), dtype))
    assert ok
    path = tmp_path / "frame.tif"
    path.write_bytes(buf.tobytes())
    img, reason = read_image(path)
    assert img is not None and img.dtype == dtype  # read_image gives what OpenCV decodes
    grey, reason = load_grey(path)
    if dtype == np.float64:
        assert grey is not None and grey.dtype == np.uint8 and (grey == 255).all()
    else:
        assert (grey, reason) == (None, "unsupported_image_format")


def test_a_path_with_a_nul_is_unreadable_not_an_exception():
    """Path.read_bytes raised ValueError (embedded null byte)."""
    assert read_image("frame\x00.png") == (None, "unreadable_file")
    assert load_grey("frame\x00.png") == (None, "unreadable_file")
