"""What the data-file and image fuzzers found (issue 13), one regression test each."""

from __future__ import annotations

import pytest

from controller.errors import InputError
from controller.sky.io import read_csv_record
from controller.sunpath.io import read_observations


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
