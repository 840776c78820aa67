"""A SCADA `Calibrate` on a CANopen row: the node homes through its index (HOMED clear
meanwhile) and the loop takes it back on the sun without calling anything a fault.  The
emulator's homing had been instant, so the loop's rules for an axis that homes had never
met one."""

from __future__ import annotations

from firmware_protocol import Status
from tests.controller.test_loop_canopen_held import row  # noqa: F401  (the fixture)


def test_a_canopen_row_homes_and_comes_back_on_the_sun(row):  # noqa: F811
    assert [row.cycle().health for _ in range(2)] == ["ok", "ok"]
    start = row.fw.true_angles()[0]
    assert abs(start) > 5.0  # away from the index at 0 deg, so the homing has a way to go
    row.ctl.set_override(None, "Calibrate", None, None)
    sent = row.cycle()  # HOME, then the exchange reads the node
    assert sent.health == "ok" and not sent.status & Status.HOMED
    path = []
    for _ in range(int(row.cfg.control.period_s)):  # the period after, second by second
        row.clock.sleep(1.0)
        path.append(row.fw.true_angles()[0])
    assert min(abs(a) for a in path) < 0.2, path  # it went through the index
    recs = [row.loop.run_until_complete(row.ctl.cycle())[0]] + [row.cycle() for _ in range(3)]
    assert all(r.health == "ok" for r in recs), [(r.health, r.health_reason) for r in recs]
    assert all(r.status & Status.HOMED for r in recs) and not row.fw.axes[0].homing
    assert abs(row.fw.true_angles()[0] - recs[-1].targets_deg[0]) < 1.5  # back on the sun
