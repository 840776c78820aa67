import pytest

from controller.config import load_config
from controller.errors import ConfigError
from tests.conftest import DEFAULT_CONFIG


def test_default_config_loads():
    cfg = load_config(DEFAULT_CONFIG)
    assert cfg.site.latitude == pytest.approx(32.4835)
    assert [t.type for t in cfg.trackers] == ["dual-axis", "single-axis"]
    assert cfg.control.heartbeat_timeout_s > cfg.control.period_s


def write(tmp_path, text):
    p = tmp_path / "bad.toml"
    p.write_text(text)
    return p


BASE = """
[site]
latitude = 10
longitude = 20
[[links]]
name = "a"
kind = "modbus-rtu"
[[trackers]]
name = "t"
type = "dual-axis"
link = "a"
device_id = 1
"""


@pytest.mark.parametrize("mutate, key, expected", [
    (lambda s: s.replace("latitude = 10", "latitude = 100"), "site.latitude", "[-90, 90]"),
    (lambda s: s.replace("latitude = 10", 'latitude = "north"'), "site.latitude", "a number"),
    (lambda s: s.replace('link = "a"', 'link = "b"'), "trackers[0].link", "[[links]]"),
    (lambda s: s.replace("device_id = 1", "device_id = 300"), "trackers[0].device_id", "[1, 247]"),
    (lambda s: s.replace('type = "dual-axis"', 'type = "tri-axis"'), "trackers[0].type", "dual-axis"),
    (lambda s: s + "[control]\nperiod_s = 60\nheartbeat_timeout_s = 30\n", "control.heartbeat_timeout_s", "more than"),
    (lambda s: s + "[control]\nperiod = 60\n", "control.period", "known keys"),
    (lambda s: s.replace("[site]\nlatitude = 10\n", "[site]\n"), "site.latitude", "missing"),
    (lambda s: s + '[hotspot]\ncalibration = "b.toml"\ninterval_s = -5\n', "hotspot.interval_s",
     "[0, 86400] s"),
])
def test_errors_name_file_key_and_expectation(tmp_path, mutate, key, expected):
    path = write(tmp_path, mutate(BASE))
    with pytest.raises(ConfigError) as e:
        load_config(path)
    msg = str(e.value)
    assert str(path) in msg and key in msg and expected in msg


def test_diffuse_needs_a_pyranometer_and_minute_sampling(tmp_path):
    with pytest.raises(ConfigError, match="diffuse.enabled.*pyranometer"):
        load_config(write(tmp_path, BASE + "[diffuse]\nenabled = true\n"))
    text = DEFAULT_CONFIG.read_text().replace("period_s = 60.0", "period_s = 120.0")
    with pytest.raises(ConfigError, match="every minute"):
        load_config(write(tmp_path, text))


def test_syntax_error_and_missing_file(tmp_path):
    with pytest.raises(ConfigError, match="valid TOML"):
        load_config(write(tmp_path, "[site\nlatitude = 1"))
    with pytest.raises(ConfigError, match="readable"):
        load_config(tmp_path / "nope.toml")


def test_duplicate_device_on_a_link_is_refused(tmp_path):
    text = BASE + '[[trackers]]\nname = "u"\ntype = "single-axis"\nlink = "a"\ndevice_id = 1\n'
    with pytest.raises(ConfigError, match=r"trackers\[1\].device_id"):
        load_config(write(tmp_path, text))
