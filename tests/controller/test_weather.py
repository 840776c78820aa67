"""Wind stow hysteresis, dwell and the lost-anemometer timeout; the flag file; config checks."""

import pytest

from controller.errors import ConfigError
from controller.schema import load
from controller.weather import WindConfig, WindMonitor, WindSample, read_flag_file

CFG = WindConfig(
    link="rs485",
    device_id=11,
    gust_stow_m_s=20,
    mean_stow_m_s=14,
    gust_resume_m_s=15,
    mean_resume_m_s=10,
    resume_dwell_s=600,
    poll_s=5,
    silent_timeout_s=60,
)


def s(t, gust, mean=5.0):
    return WindSample(t, gust * 0.7, gust, mean)


def test_gust_enters_then_resume_needs_calm_for_the_dwell():
    m = WindMonitor(CFG, 0.0)
    assert not m.update(5, s(5, 19.9)).stow
    st = m.update(10, s(10, 20.0))
    assert st.stow and st.alarm and "gust 20.0" in st.reason
    assert m.update(15, s(15, 16.0)).stow  # below stow, above resume: stays
    assert m.update(20, s(20, 14.0)).stow  # calm from t=20 ...
    assert m.update(300, s(300, 14.0)).stow
    assert m.update(400, s(400, 17.0)).stow  # a gust above resume restarts the dwell
    assert m.update(410, s(410, 10.0)).stow
    assert m.update(1009, s(1009, 10.0)).stow
    assert not m.update(1010, s(1010, 10.0)).stow  # 600 s of calm


def test_the_ten_minute_mean_alone_stows():
    m = WindMonitor(CFG, 0.0)
    assert m.update(5, s(5, 17.0, mean=14.0)).stow
    assert m.update(600, s(600, 14.0, mean=10.5)).stow  # mean above its resume threshold


def test_a_silent_anemometer_stows_after_the_timeout_and_alarms():
    m = WindMonitor(CFG, 0.0)
    assert not m.update(59, None).stow
    st = m.update(60, None)
    assert st.stow and st.alarm and "anemometer silent for 60 s" in st.reason
    assert m.update(65, s(65, 3.0)).stow  # back, but calm must last the dwell
    assert not m.update(665, s(665, 3.0)).stow
    ignore = WindMonitor(WindConfig(**{**CFG.__dict__, "on_silence": "ignore"}), 0.0)
    st = ignore.update(60, None)
    assert not st.stow and st.alarm


def test_config_checks_name_the_key():
    with pytest.raises(ConfigError, match=r"wind.gust_resume_m_s: expected less than gust_stow_m_s"):
        load(WindConfig, {"link": "a", "device_id": 3, "gust_resume_m_s": 25}, "p.toml", "wind")
    with pytest.raises(ConfigError, match=r"wind.silent_timeout_s"):
        load(WindConfig, {"link": "a", "device_id": 3, "poll_s": 10, "silent_timeout_s": 5}, "p.toml", "wind")


@pytest.mark.parametrize(
    "text, expected",
    [
        ("snow\n", "snow"),
        ("HAIL until 18:00", "hail"),
        ("none", None),
        ("", None),
    ],
)
def test_flag_file(tmp_path, text, expected):
    p = tmp_path / "stow.flag"
    p.write_text(text)
    assert read_flag_file(p) == expected
    assert read_flag_file(tmp_path / "absent") is None


def test_a_flag_file_with_nonsense_is_reported_not_obeyed(tmp_path):
    p = tmp_path / "stow.flag"
    p.write_text("tornado")
    assert "is not snow, hail or none" in read_flag_file(p)
