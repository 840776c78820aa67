"""The HIL's scripted wind and the emulated anemometer's registers."""

import numpy as np

from firmware_protocol import decode
from firmware_protocol.anemometer import ANE
from hil.anemometer import Anemometer
from hil.wind import STORM_DAY_START_S, Storm, WindScript


def test_wind_is_a_function_of_time_only():
    w = WindScript(0.0, ("gusty",), seed=3)
    t = 1000.0 + np.arange(0, 60, 0.25)
    assert np.array_equal(w.speed(t), np.concatenate([w.speed(t[:100]), w.speed(t[100:])]))


def test_gust_factor_and_storm_profile():
    w = WindScript(0.0, ("calm", "storm"), seed=1)
    calm = w.speed(10 * 3600 + np.arange(0, 3600, 0.25))
    assert 1.5 < calm.mean() < 4.5
    peak = 86400 + STORM_DAY_START_S + 1800 + 1800  # mid-hold of the storm day
    assert 16 < w.mean_10min(peak) < 22
    assert 1.25 < w.gust(peak) / w.mean_10min(peak) < 1.8
    before = 86400 + STORM_DAY_START_S - 600
    assert w.gust(before) < 15
    extra = WindScript(0.0, ("calm",), storms=(Storm(5000.0, peak_m_s=25.0),))
    assert extra.mean_10min(5000 + 1800 + 900) > 20


def test_anemometer_registers_and_injected_faults():
    w = WindScript(0.0, ("gusty",), seed=2)
    t = [43200.0]
    a = Anemometer(w, lambda: t[0])
    words = a.read(0, 7)
    assert decode(ANE["ANE_GUST"], [words[2]]) >= decode(ANE["ANE_MEAN_10MIN"], [words[3]]) * 0.9
    count = words[5]
    t[0] += 1.0
    assert a.read(0, 7)[5] == (count + 4) % 65536  # 4 Hz sampling
    a.frozen_at = t[0]
    t[0] += 10.0
    assert a.read(0, 7)[5] == (count + 4) % 65536  # frozen: the counter stops
    a.override = 90.0
    assert a.read(0, 7)[6] & 2  # out of range
