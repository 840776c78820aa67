"""Snow and hail stow requests outlive a restart of ``run`` (heliotrack/stow_requests.py):
a SCADA's StowReq had read 0 after a restart, and the plant tracked again under the snow
(a SCADA integrator's audit)."""

from __future__ import annotations

import json
import logging
import signal
import socket
import time
from pathlib import Path

from pymodbus.client import ModbusTcpClient

from controller.sunspec.models import SunSpecMap
from controller.sunspec.vendor import WEATHER_MODEL_ID
from heliotrack.stow_requests import FILE_NAME, note_stow_requests, restore_stow_requests
from tests.heliotrack.plant_emulators import heliotrack
from tests.heliotrack.test_bus_claims import free_port, tcp_plant


def test_kept_requests_are_written_on_change_and_put_back(default_plant, tmp_path, caplog):
    _run, ctl, _fws, _clock, _cfg = default_plant
    assert note_stow_requests(ctl, tmp_path, None) == {}
    ctl.safety.request("sunspec", "snow")
    ctl.safety.request("flag file", "hail")  # read again every cycle: not kept
    last = note_stow_requests(ctl, tmp_path, {})
    assert last == {"sunspec": "snow"}
    assert json.loads((tmp_path / FILE_NAME).read_text())["requests"] == {"sunspec": "snow"}
    ctl.safety.requests.clear()  # a restart
    with caplog.at_level(logging.WARNING):
        assert restore_stow_requests(ctl, tmp_path) == {"sunspec": "snow"}
    assert ctl.safety.requests == {"sunspec": "snow"} and ctl.safety.order().kind == "snow"
    assert "snow stow requested by sunspec before the restart" in caplog.text
    ctl.safety.request("sunspec", None)  # SCADA withdraws it: the record follows
    assert note_stow_requests(ctl, tmp_path, last) == {}
    ctl.safety.requests.clear()
    assert restore_stow_requests(ctl, tmp_path) == {} and ctl.safety.requests == {}


def test_a_record_that_cannot_be_read_is_one_warning_and_no_request(default_plant, tmp_path, caplog):
    _run, ctl, _fws, _clock, _cfg = default_plant
    for text in ("{not json", '{"requests": ["snow"]}', '{"requests": {"sunspec": "sleet", "x": "snow"}}'):
        (tmp_path / FILE_NAME).write_text(text)
        with caplog.at_level(logging.WARNING):
            assert restore_stow_requests(ctl, tmp_path) == {}
        assert ctl.safety.requests == {}
    assert restore_stow_requests(ctl, None) == {}


def sunspec_plant(folder) -> tuple[Path, int]:
    """A plant file whose drives are silent (what SCADA commands is what is judged), serving
    writable SunSpec on a free port of 127.0.0.1; and that port."""
    cfg = tcp_plant(folder, free_port())
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        port = s.getsockname()[1]
    cfg.write_text(cfg.read_text() + f"\n[sunspec]\nenabled = true\nport = {port}\nwrites_enabled = true\n")
    return cfg, port


def served(proc, port: int) -> ModbusTcpClient:
    """A client connected to the SunSpec server of ``run`` process ``proc``."""
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=2)
    for _ in range(100):
        if client.connect():
            return client
        assert proc.poll() is None, proc.stderr.read()
        time.sleep(0.1)
    raise AssertionError("SunSpec never served")


def commanded_then_restarted(cfg: Path, port: int, state: Path, kept: str, command):
    """``run`` on ``cfg`` given ``command(client)`` over SunSpec until ``state / kept`` is
    written, stopped (SIGTERM, exit 0) and started again for 3 s: the second process and a
    client connected to it."""
    first = heliotrack("run", "--config", str(cfg), "--state", str(state))
    try:
        client = served(first, port)
        command(client)
        for _ in range(50):  # applied and kept at the next cycle (1 s)
            if (state / kept).exists():
                break
            time.sleep(0.1)
        client.close()
        first.send_signal(signal.SIGTERM)
        assert first.wait(20) == 0
    finally:
        if first.poll() is None:
            first.kill()
    second = heliotrack("run", "--config", str(cfg), "--state", str(state), "--duration", "3")
    try:
        return second, served(second, port)
    except BaseException:
        second.kill()
        raise


def test_scadas_snow_stow_survives_a_restart_of_run(tmp_path):
    cfg, port = sunspec_plant(tmp_path)
    stow_req = SunSpecMap(1).slot("StowReq", model=WEATHER_MODEL_ID).address

    def snow(client):
        assert not client.write_register(stow_req, 1, device_id=1).isError()  # 1: snow

    second, client = commanded_then_restarted(cfg, port, tmp_path / "state", FILE_NAME, snow)
    try:
        assert client.read_holding_registers(stow_req, count=1, device_id=1).registers == [1]
        client.close()
        _, err = second.communicate(timeout=30)
        assert "snow stow requested by sunspec before the restart: in force until withdrawn" in err
    finally:
        if second.poll() is None:
            second.kill()
