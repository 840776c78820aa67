"""``heliotrack simulate --realtime --duration D --sunspec``: SunSpec is served for the whole
D seconds whatever the control period (a period longer than D used to end the run at the
first cycle boundary, or make it wait a whole period)."""

from __future__ import annotations

import time
from pathlib import Path

from pymodbus.client import ModbusTcpClient

from tests.heliotrack.plant_emulators import heliotrack
from tests.heliotrack.test_cli import short_config

DURATION_S, PERIOD_S = 6.0, 30.0
SUNS = [0x5375, 0x6E53]  # "SunS" at 40000


def _suns(port: int) -> bool:
    client = ModbusTcpClient("127.0.0.1", port=port, timeout=0.5, retries=0)
    try:
        if not client.connect():
            return False
        rr = client.read_holding_registers(40000, count=2, device_id=1)
        return not rr.isError() and list(rr.registers) == SUNS
    except Exception:  # noqa: BLE001 - a refused or dropped connection is "not served"
        return False
    finally:
        client.close()


def test_sunspec_is_served_for_the_whole_duration_with_a_longer_period(tmp_path):
    cfg = short_config(tmp_path, period=PERIOD_S)
    proc = heliotrack(
        "simulate",
        "--config",
        str(cfg),
        "--realtime",
        "--duration",
        str(DURATION_S),
        "--sunspec",
        "127.0.0.1:0",
    )
    try:
        first = proc.stdout.readline().strip()
        t0 = time.monotonic()  # the server is up from here; the run ends DURATION_S later
        assert first.startswith("SUNSPEC 127.0.0.1:"), first + proc.stderr.read()
        port = int(first.rsplit(":", 1)[1])
        polls: list[tuple[float, bool]] = []
        while proc.poll() is None and time.monotonic() - t0 < DURATION_S + 10:
            polls.append((time.monotonic() - t0, _suns(port)))
            time.sleep(0.2)
        out, err = proc.communicate(timeout=10)
        ended = time.monotonic() - t0
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    served = [t for t, ok in polls if ok]
    assert served, (polls, err)
    # served without a gap until the last second of the run, and the run ended on time
    assert served[-1] >= DURATION_S - 1.0, polls
    assert all(ok for t, ok in polls if t <= served[-1]), polls
    assert ended < DURATION_S + 5.0, (ended, out)
    assert "realtime: 1 cycles" in out, out  # one cycle at the start, none due before the end
    # the two drives and the pyranometer of one RS-485 line open its port once, not in a race
    assert "WARNING" not in err, err
    # an operator's session logs at INFO by default, so SCADA's accepted writes are seen
    # (an audit's finding: at WARNING nothing of SCADA's actions was kept)
    assert "INFO    heliotrack.sunspec: SunSpec server on 127.0.0.1:" in err, err


def test_a_wind_scenario_reads_its_anemometer_and_serves_the_wind(tmp_path):
    """A SCADA integrator's finding: on config/hil-storm.toml, ``simulate --realtime``
    built no emulated anemometer and gave the controller none to poll, so the plant ran
    with [wind] but no wind protection, and model 64601 read no wind and no alarm for the
    whole run."""
    from controller.sunspec.models import SunSpecMap

    storm = Path(__file__).resolve().parents[2] / "config" / "hil-storm.toml"
    cfg = tmp_path / "storm.toml"
    cfg.write_text(storm.read_text().replace("period_s = 60.0", "period_s = 2.0"))
    proc = heliotrack(
        "simulate", "--config", str(cfg), "--realtime", "--duration", "12", "--sunspec", "127.0.0.1:0"
    )
    wind_spd = SunSpecMap(3).slot("WindSpd", model=64601).address  # hil-storm: 3 trackers
    seen: list[int] = []
    try:
        first = proc.stdout.readline().strip()
        assert first.startswith("SUNSPEC 127.0.0.1:"), first + proc.stderr.read()
        client = ModbusTcpClient("127.0.0.1", port=int(first.rsplit(":", 1)[1]), timeout=1, retries=0)
        assert client.connect()
        try:
            t0 = time.monotonic()
            while time.monotonic() - t0 < 11 and not any(w != 0xFFFF for w in seen):
                rr = client.read_holding_registers(wind_spd, count=3, device_id=1)
                seen.extend(rr.registers if not rr.isError() else [])
                time.sleep(0.5)
        finally:
            client.close()
        _out, err = proc.communicate(timeout=30)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, err
    assert any(w != 0xFFFF for w in seen), seen  # WindSpd, WindGst, WindAvg read
