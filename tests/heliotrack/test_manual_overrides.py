"""SCADA's Manual overrides outlive a restart of ``run`` (heliotrack/manual_overrides.py): a
row held in Manual for maintenance had gone back to tracking after a restart, ``Ctl = 0``."""

from __future__ import annotations

import json
import logging
from dataclasses import replace

from controller.sunspec.models import SunSpecMap
from heliotrack.manual_overrides import FILE_NAME, note_overrides, restore_overrides
from tests.heliotrack.test_stow_requests import commanded_then_restarted, sunspec_plant


def test_overrides_are_written_on_change_and_put_back(default_plant, tmp_path, caplog):
    _run, ctl, _fws, _clock, _cfg = default_plant
    assert note_overrides(ctl, tmp_path, None) == {}
    ctl.set_override(1, "Manual", 20.0, None)  # the row
    ctl.set_override(0, "Manual", 35.0, 200.0)  # the dual-axis tracker: azimuth, elevation
    last = note_overrides(ctl, tmp_path, {})
    assert last == {"dual-1": [200.0, 35.0], "row-1": [20.0]}
    assert json.loads((tmp_path / FILE_NAME).read_text())["overrides"] == last
    ctl.overrides.clear()  # a restart
    with caplog.at_level(logging.WARNING):
        assert restore_overrides(ctl, tmp_path) == last
    assert ctl.overrides == {0: (200.0, 35.0), 1: (20.0,)}
    assert "row-1: Manual at 20 deg, set before the restart: held until Automatic" in caplog.text
    ctl.set_override(1, "Automatic", None, None)  # released: the record follows
    assert note_overrides(ctl, tmp_path, last) == {"dual-1": [200.0, 35.0]}
    ctl.overrides.clear()
    assert restore_overrides(ctl, tmp_path) == {"dual-1": [200.0, 35.0]}


def test_a_kept_override_is_clamped_into_the_travel_of_today(default_plant, tmp_path):
    _run, ctl, _fws, _clock, _cfg = default_plant
    (tmp_path / FILE_NAME).write_text(json.dumps({"overrides": {"row-1": [50.0]}}))
    row = ctl.trackers[1]
    row.cfg = replace(row.cfg, max_angle=45.0)  # the travel narrowed between the two runs
    assert restore_overrides(ctl, tmp_path) == {"row-1": [45.0]}


def test_a_record_that_cannot_be_read_or_names_other_trackers_is_ignored(default_plant, tmp_path, caplog):
    _run, ctl, _fws, _clock, _cfg = default_plant
    for text in (
        "{not json",
        '{"overrides": [20]}',
        '{"overrides": {"row-9": [20.0], "row-1": [20.0, 5.0], "dual-1": [NaN, 10.0]}}',
        '{"overrides": {"row-1": ["20"], "dual-1": true}}',
    ):
        (tmp_path / FILE_NAME).write_text(text)
        with caplog.at_level(logging.WARNING):
            assert restore_overrides(ctl, tmp_path) == {}
        assert ctl.overrides == {}
    assert "'row-9': [20.0] is no tracker of this plant; ignored" in caplog.text
    assert "'row-1': [20.0, 5.0] is not 1 angle(s) in deg; ignored" in caplog.text
    assert restore_overrides(ctl, None) == {}


def test_scadas_manual_override_survives_a_restart_of_run(tmp_path):
    cfg, port = sunspec_plant(tmp_path)
    m = SunSpecMap(1)
    ctl_reg, el_reg = m.slot("Ctl", 0).address, m.slot("ElCtl", 0).address
    state = tmp_path / "state"

    def manual(client):
        assert not client.write_registers(el_reg, [0, 30000], device_id=1).isError()  # 30 deg (0.001)
        assert not client.write_register(ctl_reg, 1, device_id=1).isError()  # 1: Manual

    second, client = commanded_then_restarted(cfg, port, state, FILE_NAME, manual)
    try:
        assert json.loads((state / FILE_NAME).read_text())["overrides"]["dual-1"][1] == 30.0
        assert client.read_holding_registers(ctl_reg, count=1, device_id=1).registers == [1]
        assert client.read_holding_registers(el_reg, count=2, device_id=1).registers == [0, 30000]
        client.close()
        _, err = second.communicate(timeout=30)
        assert "dual-1: Manual at" in err and "set before the restart: held until Automatic" in err, err
    finally:
        if second.poll() is None:
            second.kill()
