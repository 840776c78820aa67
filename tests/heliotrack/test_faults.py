"""[hil.faults]: the schema, the scheduler that switches faults in the world on the simulated
clock, and the ledger that follows each fault to the rows' recovery."""

import math
from contextlib import ExitStack
from dataclasses import replace
from datetime import UTC, datetime

import pytest

from controller.clock import SimClock
from controller.errors import ConfigError
from heliotrack.fault_ledger import FaultLedger
from heliotrack.faults import FaultScheduler, unexpected_error
from heliotrack.scenario import parse_scenario
from heliotrack.world import build_world

T0 = datetime(2024, 3, 20, 8, 0, tzinfo=UTC).timestamp()


def scenario(faults: dict, **extra):
    doc = {
        "site": {"latitude": 32.5, "longitude": 48.3},
        "links": [
            {"name": "rs485-1", "kind": "modbus-rtu", "port": "hil"},
            {"name": "can-1", "kind": "canopen", "channel": "hil"},
        ],
        "control": {"heartbeat_timeout_s": 65.0},
        "trackers": [
            {"name": "dual-1", "type": "dual-axis", "link": "rs485-1", "device_id": 1},
            {"name": "row-1", "type": "single-axis", "link": "rs485-1", "device_id": 2},
            {"name": "row-can", "type": "single-axis", "link": "can-1", "device_id": 5},
        ],
        "pyranometer": {"link": "rs485-1", "device_id": 10},
        "hil": {"faults": faults},
        **extra,
    }
    return parse_scenario(doc, "<test>")


def at(seconds: float) -> str:
    return datetime.fromtimestamp(T0 + seconds, UTC).isoformat()


# -- schema ---------------------------------------------------------------------------------------
def test_the_faults_table_is_validated_with_the_key_named():
    cfg = scenario(
        {
            "seed": 3,
            "per_transaction": {"crc_error": 1e-3},
            "random": [{"type": "drive_stall", "per_hour": 0.5}],
        }
    )
    assert cfg.hil.faults.enabled and cfg.hil.faults.random[0].durations() == (30.0, 300.0)
    assert not scenario({}).hil.faults.enabled
    with pytest.raises(ConfigError, match=r"hil\.faults\.random\[0\]\.type"):
        scenario({"random": [{"type": "cosmic_ray", "per_hour": 1}]})
    with pytest.raises(
        ConfigError, match=r"hil\.faults\.events\[0\]\.target: expected something a drive_stall"
    ):
        scenario({"events": [{"type": "drive_stall", "at": at(0), "target": "row-9"}]})
    with pytest.raises(ConfigError, match=r"hil\.faults\.events\[0\]\.at"):
        scenario({"events": [{"type": "drive_stall", "at": "10:00"}]})
    with pytest.raises(ConfigError, match=r"duration_s: expected \[min, max\]"):
        scenario({"random": [{"type": "limit_switch", "per_hour": 1, "duration_s": [60, 10]}]})
    with pytest.raises(ConfigError, match=r"per_transaction\.late_reply"):
        scenario({"per_transaction": {"late_reply": 2}})


@pytest.mark.parametrize(
    ("faults", "key"),
    [
        (
            {"events": [{"type": "wall_clock_step", "at": at(0), "magnitude": 1e12}]},
            r"events\[0\]\.magnitude",
        ),
        (
            {"random": [{"type": "encoder_glitch", "per_hour": 1, "magnitude": [-1e308, 1e308]}]},
            r"random\[0\]\.magnitude",
        ),
        (
            {"random": [{"type": "pyranometer_out_of_range", "per_hour": 1, "magnitude": [1e5, 2e5]}]},
            r"random\[0\]\.magnitude",
        ),
    ],
)
def test_a_fault_magnitude_beyond_what_its_target_can_hold_is_refused(faults, key):
    """An audit's cases: a clock step of 1e12 s and a glitch of 1e308 deg had passed
    validation and crashed the run (a year 33712, an int overflow)."""
    with pytest.raises(ConfigError, match=rf"hil\.faults\.{key}: expected a \w+ magnitude within"):
        scenario(faults)
    scenario({"events": [{"type": "wall_clock_step", "at": at(0), "magnitude": -3600.0}]})


def test_an_empty_wind_cycle_is_refused_as_an_empty_sky_cycle_is():
    with pytest.raises(ConfigError, match=r"hil\.wind\.days: expected at least one wind kind"):
        scenario({}, hil={"wind": {"days": []}})


def test_a_first_day_centuries_away_is_refused():
    with pytest.raises(
        ConfigError, match=r"hil\.start: expected a day in the years 1900-2200, got '2420-03-20'"
    ):
        scenario({}, hil={"start": "2420-03-20"})


# -- the ledger -------------------------------------------------------------------------------------
def test_a_fault_survives_when_its_rows_are_back_in_service_after_it_cleared():
    ledger = FaultLedger(["a", "b"], period_s=60.0)
    ledger.started("drive_stall", ["a"])
    ledger.judge(60.0, {"a": True, "b": True})  # in service while on: not back yet
    assert ledger.survived["drive_stall"] == 0
    ledger.ended("drive_stall", ["a"], 100.0)
    ledger.judge(120.0, {"a": False, "b": True})
    ledger.judge(180.0, {"a": True, "b": True})
    assert ledger.survived["drive_stall"] == 1
    assert ledger.recovery_worst_s["drive_stall"] == pytest.approx(80.0)
    assert ledger.worst_periods() == pytest.approx(80.0 / 60.0, abs=1e-3)


def test_a_plant_fault_waits_for_every_row_and_recovery_counts_from_the_last_clearing():
    ledger = FaultLedger(["a", "b"], period_s=60.0)
    ledger.started("wall_clock_step", ["a", "b"])
    ledger.ended("wall_clock_step", ["a", "b"], 60.0)
    ledger.instant("crc_error", ["b"], 90.0)
    ledger.judge(120.0, {"a": True, "b": False})
    assert ledger.survived["wall_clock_step"] == 0
    ledger.judge(180.0, {"a": True, "b": True})
    assert ledger.survived["wall_clock_step"] == 1 and ledger.survived["crc_error"] == 1
    assert ledger.recovery_worst_s["crc_error"] == pytest.approx(90.0)
    # row b came back at 180, its last fault (the CRC error) cleared at 90; row a at 120
    assert ledger.worst_periods(plant=True) == pytest.approx(1.5)
    # which row and which faults, for a soak to say where the slowest recovery was
    assert ledger.worst_event == {
        "row": "b",
        "faults": ["crc_error", "wall_clock_step"],
        "cleared_at": 90.0,
        "back_at": 180.0,
        "seconds": 90.0,
    }
    summary = ledger.summary(["crc_error", "wall_clock_step", "drive_stall"], t_end=180.0)
    assert summary["injected"] == summary["survived"] == 2
    assert summary["by_type"]["drive_stall"] == {
        "injected": 0,
        "survived": 0,
        "open_at_end": 0,
        "recovery_worst_periods": None,
    }


def test_wire_faults_in_a_cycle_it_survived_cost_no_period_and_cut_no_row_off():
    ledger = FaultLedger(["a"], period_s=60.0)
    ledger.instant("split_reply", ["a"], 60.0, n=3)
    assert not ledger.reachable("a")  # its replies were hit in this cycle
    ledger.judge(60.0, {"a": True})
    assert ledger.survived["split_reply"] == 3 and ledger.recovery_worst_s["split_reply"] == 0.0
    assert ledger.reachable("a") and ledger.after_faults("a")
    ledger.instant("crc_error", [], 70.0)  # a sensor's reply: no row to wait for
    assert ledger.survived["crc_error"] == 1
    ledger.started("emulator_restart", ["a"])
    assert not ledger.reachable("a")
    ledger.ended("emulator_restart", ["a"], 100.0)
    assert ledger.open_at_end(110.0)["emulator_restart"] == 1
    assert not ledger.open_at_end(300.0)  # cleared long before the end: lost, not open


def test_an_unexpected_exception_in_a_row_is_told_from_a_link_error():
    from controller.loop import CycleRecord

    rec = CycleRecord(0.0, "row-1", "TRACK", "", "ephemeris", 0.0, 0.0)
    rec.error = "row-1: IndexError: list index out of range"
    assert unexpected_error(rec) == "IndexError"
    for text in (
        "/dev/pts/3 id 2: state read failed after 3 attempt(s): Timeout",
        "row-1: exchange not done within the cycle's 30 s (no answer, or answers and retries slower than the period allows)",
        "",
    ):
        rec.error = text
        assert unexpected_error(rec) is None


# -- the scheduler -----------------------------------------------------------------------------------------
@pytest.fixture
def world_with(request):
    """(scheduler, world, clock) for the scenario's faults, on a real emulated world."""

    def make(faults: dict, hours: float = 1.0):
        cfg = scenario(faults)
        clock = SimClock(T0)
        stack = ExitStack()
        request.addfinalizer(stack.close)
        world = build_world(cfg, cfg.hil, clock, stack, ghi_at=lambda t: 500.0)
        return FaultScheduler(cfg, world, clock, T0, T0 + hours * 3600), world, clock

    return make


def step(sched, clock, seconds):
    clock.advance_to(T0 + seconds)
    sched.advance(T0 + seconds)


def test_scheduled_faults_go_on_and_off_in_the_world(world_with):
    events = [
        {"type": "drive_stall", "at": at(100), "duration_s": 60, "target": "row-1"},
        {"type": "limit_switch", "at": at(100), "duration_s": 60, "target": "dual-1"},
        {"type": "emulator_restart", "at": at(300), "duration_s": 30, "target": "row-1"},
        {"type": "emulator_restart", "at": at(300), "duration_s": 30, "target": "row-can"},
        {"type": "can_bus_off", "at": at(500), "duration_s": 20, "target": "can-1"},
        {"type": "modbus_timeout", "at": at(600), "duration_s": 20, "target": "dual-1"},
        {"type": "pyranometer_nan", "at": at(700), "duration_s": 20},
        {"type": "wall_clock_step", "at": at(800), "duration_s": 60, "magnitude": -3600},
    ]
    sched, world, clock = world_with({"events": events})
    step(sched, clock, 50)
    assert not world.firmwares["row-1"].axes[0].jammed
    step(sched, clock, 100)
    stalled = world.firmwares["row-1"]
    assert stalled.axes[0].jammed and any(ax.hard_limit for ax in world.firmwares["dual-1"].axes)
    step(sched, clock, 165)
    assert not stalled.axes[0].jammed and not any(ax.limit_stuck for ax in world.firmwares["dual-1"].axes)
    step(sched, clock, 300)
    slot = world.faults.drives["row-1"].slot
    assert slot is not None and not slot.powered and world.faults.drives["row-can"].node is None
    step(sched, clock, 335)
    assert slot.powered and world.firmwares["row-1"] is not stalled and stalled in world.retired
    assert world.faults.drives["row-can"].node is not None
    assert world.firmwares["row-1"].heartbeat_timeout == 10.0  # factory setting, not configured
    step(sched, clock, 500)
    assert world.faults.can["can-1"].state == "bus_off"
    step(sched, clock, 525)
    assert world.faults.can["can-1"].state is None
    step(sched, clock, 600)
    assert world.faults.wire["rs485-1"].forced == {1: "modbus_timeout"}
    step(sched, clock, 625)
    assert not world.faults.wire["rs485-1"].forced
    step(sched, clock, 700)
    assert world.pyranometer is not None and math.isnan(world.pyranometer.override)
    step(sched, clock, 725)
    assert world.pyranometer.override is None
    step(sched, clock, 800)
    assert clock.now() == pytest.approx(clock.monotonic() - 3600)
    step(sched, clock, 865)
    assert clock.now() == pytest.approx(clock.monotonic())
    assert sum(sched.ledger.injected.values()) == len(events)


def test_random_faults_are_a_seeded_poisson_process_on_possible_targets(world_with):
    spec = {
        "seed": 5,
        "random": [{"type": "drive_stall", "per_hour": 2.0}, {"type": "can_bus_off", "per_hour": 1.0}],
    }
    a, _, _ = world_with(spec, hours=50)
    b, _, _ = world_with(spec, hours=50)
    c, _, _ = world_with({**spec, "seed": 6}, hours=50)
    plan = [(f.kind, round(f.start, 3), f.target) for f in a.plan]
    assert plan == [(f.kind, round(f.start, 3), f.target) for f in b.plan]
    assert plan != [(f.kind, round(f.start, 3), f.target) for f in c.plan]
    stalls = [f for f in a.plan if f.kind == "drive_stall"]
    assert 60 <= len(stalls) <= 140  # 100 expected
    assert {f.target for f in stalls} == {"dual-1", "row-1", "row-can"}
    assert {f.target for f in a.plan if f.kind == "can_bus_off"} == {"can-1"}
    assert all(30 <= f.duration <= 300 for f in stalls)
    by_target: dict[str, list] = {}
    for f in stalls:  # never two stalls of one drive at once
        by_target.setdefault(f.target, []).append(f)
    for fs in by_target.values():
        assert all(x.start + x.duration <= y.start for x, y in zip(fs, fs[1:]))


def test_a_plant_without_the_target_gets_none_of_that_fault(world_with):
    sched, _, _ = world_with({"random": [{"type": "anemometer_frozen", "per_hour": 10.0}]})
    assert sched.plan == []  # no [wind]: no anemometer to freeze


def test_faults_can_be_switched_off_entirely():
    cfg = scenario({})
    cfg = replace(cfg, hil=replace(cfg.hil, faults=replace(cfg.hil.faults, seed=1)))
    assert not cfg.hil.faults.enabled
