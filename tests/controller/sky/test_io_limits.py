"""Irradiance records: a stray far-off time is named, and never allocates the span."""

import numpy as np
import pytest

from controller.errors import InputError
from controller.sky.grid import build_day_grid
from controller.sky.io import read_csv_record


def test_a_time_outside_1900_2200_is_named(tmp_path):
    rows = ["time,ghi"] + [f"{1_700_000_000 + 60 * i},{i % 500}" for i in range(100)]
    rows.insert(51, "1e15,5")
    p = tmp_path / "r.csv"
    p.write_text("\n".join(rows) + "\n")
    with pytest.raises(
        InputError,
        match=r"r.csv: row 52, column 'time': expected a time between "
        r"the years 1900 and 2200 .* got 1e\+15",
    ):
        read_csv_record(p)


def test_unordered_times_far_apart_cost_a_day_each_not_the_span():
    t = np.concatenate([1_700_000_000 + 60.0 * np.arange(1440), [1e12]])[::-1]  # unordered
    grid = build_day_grid(t, np.full(t.size, 100.0), 0.0, step_s=60)
    assert grid.ghi.shape == (3, 1440)  # two days of data + the stray one
