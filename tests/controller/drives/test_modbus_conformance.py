"""``heliotrack protocol conformance`` against the emulated drive (every rule holds) and
against drives that break rules the controller relies on (each is named)."""

from __future__ import annotations

import time

import pytest

import hil.modbus_device
from heliotrack.cli import main
from hil.drive import DriveFirmware, FirmwareReject
from hil.modbus_server import ModbusServerThread
from hil.pty import PtyLink
from tests.conftest import two_axes


def plant_file(tmp_path, body: str):
    """A plant file of one link and one tracker (``body``) at a made-up site."""
    p = tmp_path / "plant.toml"
    p.write_text("[site]\nlatitude = 10.0\nlongitude = 20.0\n" + body)
    return p


def plant(tmp_path, port: str):
    return plant_file(
        tmp_path,
        f'[[links]]\nname = "rs485"\nkind = "modbus-rtu"\nport = "{port}"\ntimeout_s = 0.3\n'
        '[[trackers]]\nname = "dual-1"\ntype = "dual-axis"\nlink = "rs485"\ndevice_id = 1\n',
    )


def rows(out: str) -> dict[str, str]:
    """Check name -> its outcome."""
    return {ln.split(": ")[0][6:]: ln[:5].strip() for ln in out.splitlines() if ": " in ln and ln[:5].strip()}


def conformance(tmp_path, capsys, fw, *extra):
    with PtyLink.open() as link, ModbusServerThread({1: fw}, serial_url=link.url):
        rc = main(
            [
                "protocol",
                "conformance",
                "--config",
                str(plant(tmp_path, link.path)),
                "--tracker",
                "dual-1",
                *extra,
            ]
        )
    return rc, capsys.readouterr().out


def test_the_emulated_drive_passes_every_rule(tmp_path, capsys):
    fw = DriveFirmware(two_axes(), time.time, monotonic=time.monotonic, heartbeat_timeout=5.0)
    rc, out = conformance(tmp_path, capsys, fw, "--may-move", "--watchdog-s", "0.5")
    got = rows(out)
    assert rc == 0, out
    assert set(got.values()) == {"pass"}, out
    assert len(got) == 15 and out.splitlines()[-1] == "15 of 15 check(s) without a failure", out
    assert got["FC 23 heartbeat round"] == "pass", out
    assert fw.heartbeat_timeout == pytest.approx(5.0)  # put back
    assert fw.modes == [fw.modes[0].AUTO] * 2


def test_without_may_move_nothing_moves(tmp_path, capsys):
    fw = DriveFirmware(two_axes(), time.time, monotonic=time.monotonic)
    before = list(fw.true_angles())
    rc, out = conformance(tmp_path, capsys, fw)
    assert rc == 0, out
    assert list(rows(out).values()).count("skip") == 4, out
    assert fw.target_writes <= 2 and fw.true_angles() == pytest.approx(before)  # the same target written back


class _NoGaps(DriveFirmware):
    """Refuses reads of addresses no register holds (spec-compliant Modbus, not this map)."""

    def read(self, address, count):
        from hil.drive.firmware import _WORDS

        if any(a not in _WORDS for a in range(address, address + count)):
            raise FirmwareReject(2, "a gap")
        return super().read(address, count)


def test_a_drive_that_refuses_reads_across_gaps_is_named(tmp_path, capsys):
    rc, out = conformance(tmp_path, capsys, _NoGaps(two_axes(), time.time, monotonic=time.monotonic))
    assert rc == 1, out
    assert rows(out) == {"identity": "FAIL"}, out
    assert "identification read refused by the drive: exception 2" in out, out


def test_a_drive_breaking_the_rules_is_named(tmp_path, capsys, monkeypatch):
    monkeypatch.setattr(hil.modbus_device, "_REGISTER_FCS", {3, 6, 16})
    fw = DriveFirmware(two_axes(), time.time, monotonic=time.monotonic)
    apply = fw._apply_axis

    def no_clamp(name, k, value):  # a firmware that leaves the target in force outside new limits
        if name in ("SOFT_LIMIT_MIN", "SOFT_LIMIT_MAX"):
            field = {"SOFT_LIMIT_MIN": "soft_min", "SOFT_LIMIT_MAX": "soft_max"}[name]
            setattr(fw.axes[k].p, field, value)  # the limit taken, the target in force untouched
        else:
            apply(name, k, value)

    monkeypatch.setattr(fw, "_apply_axis", no_clamp)
    rc, out = conformance(tmp_path, capsys, fw, "--may-move", "--watchdog-s", "0.5")
    got = rows(out)
    assert rc == 1, out
    assert got["FC 23 exchange"] == "warn" and "the controller uses FC 16 + FC 3" in out, out
    assert got["FC 23 heartbeat round"] == "warn" and "FC 6 + FC 3 for its heartbeat round" in out, out
    assert got["new soft limits clamp the target in force"] == "FAIL", out
    assert [k for k, v in got.items() if v == "FAIL"] == ["new soft limits clamp the target in force"], out


def test_a_tracker_not_in_the_plant_or_not_on_modbus_is_one_line(tmp_path, capsys):
    p = plant(tmp_path, "/dev/null")
    assert main(["protocol", "conformance", "--config", str(p), "--tracker", "row-9"]) == 2
    assert "--tracker 'row-9': not in" in capsys.readouterr().err
