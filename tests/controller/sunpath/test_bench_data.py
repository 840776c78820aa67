"""The benchmark's data follow the paper: its 36 days, sampling and Table 4 pairs."""

import pandas as pd

from benchmarks.sunpath_common import PAPER_DATES, PAPER_TABLE4_ER_S, make_dataset, paper_samples_per_day
from controller.sunpath.days import split_days

from ._synth import ANDIMESHK


def test_paper_days_and_pairs():
    d = pd.to_datetime(list(PAPER_DATES))
    assert len(d) == 36 and d.is_monotonic_increasing
    pairs = int(((d[1:] - d[:-1]).days == 1).sum())
    assert pairs == 20 == len(PAPER_TABLE4_ER_S["1"])  # Table 4 has 20 pairs
    assert paper_samples_per_day("2024-02-12") == 35 and paper_samples_per_day("2024-06-03") == 36


def test_paper_sampling_starts_at_0800_local():
    ds = make_dataset(ANDIMESHK, 3.5, dates=PAPER_DATES[:2], clouds_per_day=0.0)
    days = split_days(ds.t, 3.5)
    assert [d.index.size for d in days] == [35, 35]
    first = (ds.t[days[0].index[0]] - days[0].midnight) / 3600.0
    last = (ds.t[days[0].index[-1]] - days[0].midnight) / 3600.0
    assert (first, last) == (8.0, 16.5)
