import math

import numpy as np
import pytest

from benchmarks.angular_error import error_stats


def test_error_stats_of_known_errors():
    s = error_stats([0.1, 0.2, 0.3, 0.4])
    assert s["n"] == 4
    assert s["rms_deg"] == pytest.approx(math.sqrt((0.01 + 0.04 + 0.09 + 0.16) / 4), abs=1e-4)
    assert s["median_deg"] == pytest.approx(0.25)
    assert s["max_deg"] == pytest.approx(0.4)
    assert s["p95_deg"] == pytest.approx(float(np.percentile([0.1, 0.2, 0.3, 0.4], 95)), abs=1e-4)


def test_error_stats_leaves_out_frames_with_no_error():
    assert error_stats([0.5, None, float("nan"), 0.5]) == error_stats([0.5, 0.5])
    assert error_stats([0.5, None])["n"] == 1


def test_error_stats_of_nothing():
    assert error_stats([]) == {"n": 0}
    assert error_stats([None, float("nan")]) == {"n": 0}
