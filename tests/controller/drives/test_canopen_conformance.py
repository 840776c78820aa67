"""``heliotrack protocol conformance`` against an emulated CANopen drive on a virtual bus
(every rule holds), and against one that breaks rules (each is named)."""

from __future__ import annotations

import time

from heliotrack.cli import main
from tests.controller.drives.test_modbus_conformance import plant_file, rows
from tests.hil.canopen.rig import emulated, one_axis


def plant(tmp_path, channel: str):
    return plant_file(
        tmp_path,
        "[control]\nperiod_s = 10.0\nheartbeat_timeout_s = 30.0\n"
        f'[[links]]\nname = "can"\nkind = "canopen"\ninterface = "virtual"\nchannel = "{channel}"\n'
        'timeout_s = 0.3\n[[trackers]]\nname = "row-1"\ntype = "single-axis"\nlink = "can"\ndevice_id = 7\n',
    )


def conformance(tmp_path, capsys, *extra, patch=None):
    with emulated(axes=one_axis(), node_id=7, now=time.time, heartbeat_timeout=30.0) as (fw, emu, ch):
        if patch:
            patch(fw, emu)
        rc = main(
            ["protocol", "conformance", "--config", str(plant(tmp_path, ch)), "--tracker", "row-1", *extra]
        )
    cap = capsys.readouterr()
    assert rc != 2, cap.err
    return rc, cap.out, fw


def test_the_emulated_canopen_drive_passes_every_rule(tmp_path, capsys):
    rc, out, fw = conformance(tmp_path, capsys, "--may-move", "--watchdog-s", "0.5")
    got = rows(out)
    assert rc == 0, out
    assert set(got.values()) == {"pass"} and len(got) == 10, out
    assert fw.modes[0].name == "AUTO"


def test_without_may_move_the_canopen_checks_move_nothing(tmp_path, capsys):
    rc, out, fw = conformance(tmp_path, capsys)
    assert rc == 0, out
    assert list(rows(out).values()).count("skip") == 2, out
    assert fw.target_writes == 0


def test_a_canopen_drive_breaking_a_rule_is_named(tmp_path, capsys):
    def no_interlock(fw, emu):  # a firmware that lets the watchdog be switched off anywhere
        check = fw._validate_together

        def lax(changes):
            if any(reg.name == "HEARTBEAT_TIMEOUT" for reg, _, _ in changes):
                return None
            return check(changes)

        fw._validate_together = lax

    rc, out, fw = conformance(tmp_path, capsys, patch=no_interlock)
    got = rows(out)
    assert rc == 1, out
    assert [k for k, v in got.items() if v == "FAIL"] == [
        "the watchdog off outside MAINTENANCE refused (0x1016:1 = 0)"
    ], out
    assert fw.heartbeat_timeout == 30.0  # put back
