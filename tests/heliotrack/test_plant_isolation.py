"""Many rows from one process: a dead or hung row never delays the others."""

import asyncio
from dataclasses import replace

import pytest

from controller.clock import RealClock
from controller.drives import open_drive
from controller.loop import Controller
from controller.sun.source import EphemerisSource
from heliotrack.plant import plant_config
from hil.plant import RowFarm

N = 12
TIMEOUT_S = 0.4


async def _cycles(ctl, n):
    out = []
    for _ in range(n):
        out.append(await ctl.cycle())
    return out


@pytest.fixture
def farm():
    f = RowFarm(N).start()
    yield f
    f.stop()


def _controller(farm):
    cfg = plant_config(N, farm.ports, period_s=1.0)
    drives = {
        tr.name: open_drive(replace(cfg.links_by_name[tr.link], timeout_s=TIMEOUT_S), tr.device_id)
        for tr in cfg.trackers
    }
    return Controller(cfg, drives, EphemerisSource(cfg.site), RealClock(), realtime=True)


@pytest.mark.parametrize("fault", ["killed", "hung"])
def test_one_faulty_row_does_not_delay_the_others(farm, fault):
    async def scenario():
        ctl = _controller(farm)
        await ctl.start()
        before = await _cycles(ctl, 3)
        assert not any(r.error for recs in before for r in recs)
        if fault == "killed":
            farm.kill(5)
        else:
            farm.firmwares[5].response_delay_s = 10.0
        after = await _cycles(ctl, 3)
        await ctl.close()
        return before, after

    _before, after = asyncio.run(scenario())
    for recs in after:
        faulty, healthy = recs[5], recs[:5] + recs[6:]
        assert faulty.error  # the row is reported, not hidden
        assert not any(r.error for r in healthy)  # nobody else fails
        # Every healthy row finished before the faulty one gave up (or failed fast):
        # their exchanges ran concurrently with it, never queued behind it.
        if fault == "hung":
            assert faulty.latency_s >= TIMEOUT_S
            assert max(r.latency_s for r in healthy) < faulty.latency_s
    # The healthy rows kept receiving fresh setpoints.
    assert all(r.targets_deg for r in after[-1][:5] + after[-1][6:])
