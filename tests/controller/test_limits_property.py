"""Every command is clamped to the axis's limits (issue 13): property tests that no sequence
of sun estimates (NaN, infinities, far-off values, none), modes (night, DIFFUSE, weather stow
of any kind), operator overrides (any floats, over SunSpec any register values) and drive
states (faults, modes, any angles) makes the controller send a target that is not finite or
lies outside the tracker's soft limits.

The loop runs for real (:class:`controller.loop.Controller`: mode, setpoints, overrides,
clamp, health, wind polling); only the wire is a recording :class:`DriveLink`."""

from __future__ import annotations

import asyncio
import math
from collections.abc import Sequence
from typing import Any

import pytest
from hypothesis import example, given
from hypothesis import strategies as st

from controller import setpoints as sp
from controller.clock import SimClock
from controller.config import Config, TrackerConfig, parse_config
from controller.drives.base import AxisState, DriveCommError, DriveLink, DriveState, LinkStats
from controller.loop import Controller
from controller.modes import ControlMode
from controller.northbound import Northbound
from controller.safety import SafetyState, clamp_targets
from controller.sun.source import SunSource
from controller.sun.types import EstimateSource, SunEstimate
from controller.sunspec.control import ControlTable, WriteRefused
from controller.sunspec.models import SunSpecMap
from controller.weather import WindSample, WindState
from firmware_protocol import Command, Fault, Mode, Status
from tests.fuzz.strategies import bounded

T0 = 1_717_236_000.0  # 2024-06-01 10:00 UTC

# -- values -----------------------------------------------------------------------------
wild = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.floats(-1000.0, 1000.0),
    st.sampled_from(
        [0.0, 90.0, -90.0, 180.0, 360.0, 720.0, -360.0, 1e300, -1e300, math.nan, math.inf, -math.inf]
    ),
)
#: What a drive can report on the wire: an int32 of 0.001 deg (Modbus and CANopen).
wire_angles = st.one_of(st.integers(-(2**31), 2**31 - 1).map(lambda r: r * 0.001), st.floats(-400.0, 800.0))


@st.composite
def plants(draw) -> Config:
    """A valid plant: a dual-axis tracker and a single-axis row of random limits, maybe wind."""
    az_lo = draw(st.floats(-360.0, 300.0))
    az_hi = draw(st.floats(az_lo + 1.0, min(az_lo + 720.0, 720.0)))
    el_lo = draw(st.floats(-10.0, 80.0))
    el_hi = draw(st.floats(el_lo + 1.0, 100.0))
    max_angle = draw(st.floats(1.0, 90.0))
    doc: dict[str, Any] = {
        "site": {"latitude": draw(st.floats(-66.0, 66.0)), "longitude": draw(st.floats(-180.0, 180.0))},
        "control": {"period_s": 60.0, "min_elevation_deg": draw(st.floats(-5.0, 45.0))},
        "links": [{"name": "l", "kind": "modbus-rtu"}],
        "trackers": [
            {
                "name": "dual",
                "type": "dual-axis",
                "link": "l",
                "device_id": 1,
                "azimuth_limits": [az_lo, az_hi],
                "elevation_limits": [el_lo, el_hi],
                "stow": [draw(st.floats(az_lo, az_hi)), draw(st.floats(el_lo, el_hi))],
            },
            {
                "name": "row",
                "type": "single-axis",
                "link": "l",
                "device_id": 2,
                "max_angle": max_angle,
                "axis_tilt": draw(st.floats(0.0, 45.0)),
                "axis_azimuth": draw(st.floats(0.0, 360.0)),
                "gcr": draw(st.floats(0.01, 1.0)),
                "backtrack": draw(st.booleans()),
                "stow": draw(st.floats(-max_angle, max_angle)),
            },
        ],
        "stow": {
            # within the tracker's travel, as the configuration requires (as for the wind's)
            "snow_dual_axis_elevation_deg": draw(st.floats(el_lo, el_hi)),
            "hail_dual_axis_elevation_deg": draw(st.floats(el_lo, el_hi)),
            "snow_single_axis_deg": draw(st.floats(-90.0, 90.0)),
            "hail_single_axis_deg": draw(st.floats(-90.0, 90.0)),
        },
    }
    if draw(st.booleans()):
        doc["wind"] = {
            "link": "l",
            "device_id": 9,
            "dual_axis_elevation_deg": draw(st.floats(el_lo, el_hi)),
            "single_axis_deg": draw(st.floats(-max_angle, max_angle)),
        }
    return parse_config(doc)


def axis_states(n: int):
    axis = st.builds(
        AxisState,
        actual_deg=wire_angles,
        target_deg=wire_angles,
        velocity_dps=st.floats(-32.0, 32.0),
        status=st.integers(0, 0x3FF).map(Status),
        fault=st.sampled_from(list(Fault)),
        mode=st.sampled_from(list(Mode)),
    )
    return st.lists(axis, min_size=n, max_size=n).map(
        lambda axes: DriveState(n, tuple(axes), Status(0) if not axes else axes[0].status)
    )


def in_limits(tracker: TrackerConfig, targets: Sequence[float], tol: float = 0.0) -> bool:
    return len(targets) == tracker.axes and all(
        math.isfinite(t) and lo - tol <= t <= hi + tol for t, (lo, hi) in zip(targets, tracker.soft_limits)
    )


# -- the wire --------------------------------------------------------------------------------
def healthy(tracker: TrackerConfig) -> DriveState:
    """A drive in AUTO, at its stow angles, without fault."""
    axes = tuple(
        AxisState(a, a, 0.0, Status.HOMED | Status.AT_TARGET, Fault.NONE, Mode.AUTO)
        for a in tracker.stow_angles
    )
    return DriveState(tracker.axes, axes, Status.HOMED | Status.AT_TARGET)


class RecordingDrive(DriveLink):
    """Records every target and configuration; answers with drive states drawn by hypothesis
    (any mode, fault, status bits and wire angle), and sometimes does not answer; without
    ``data``, always a healthy drive."""

    def __init__(self, tracker: TrackerConfig, data=None):
        self.tracker, self.data = tracker, data
        self.axis_count = 0
        self.stats = LinkStats()
        self.targets: list[list[float]] = []
        self.configured: list[dict] = []
        self.commands: list[Command] = []

    def _answer(self) -> DriveState:
        if self.data is None:
            return healthy(self.tracker)
        if self.data.draw(st.integers(0, 9)) == 0:
            raise DriveCommError(f"{self.tracker.name}: no answer (drawn)")
        return self.data.draw(axis_states(self.tracker.axes))

    async def connect(self) -> None:
        self.axis_count = self.tracker.axes

    async def close(self) -> None:
        pass

    async def read_state(self) -> DriveState:
        return self._answer()

    async def write_targets(self, angles_deg: Sequence[float]) -> None:
        self.targets.append(list(angles_deg))

    async def exchange(self, angles_deg: Sequence[float]) -> DriveState:
        await self.write_targets(angles_deg)
        return self._answer()

    async def heartbeat(self) -> None:
        pass

    async def command(self, cmd: Command) -> None:
        self.commands.append(cmd)

    async def configure(self, *, heartbeat_timeout_s=None, soft_limits=None, stow_angles=None) -> None:
        self.configured.append({"soft_limits": soft_limits, "stow_angles": stow_angles})


class DrawnSun(SunSource):
    """A sun source whose estimates hypothesis draws: sane, absurd, non-finite or none."""

    def __init__(self, data):
        self.data = data

    def estimate(self, t: float, now: float | None = None) -> SunEstimate | None:
        if self.data.draw(st.integers(0, 7)) == 0:
            return None
        az = self.data.draw(st.one_of(st.floats(0.0, 360.0), wild))
        el = self.data.draw(st.one_of(st.floats(-20.0, 90.0), wild))
        return SunEstimate(t, az, el, source=self.data.draw(st.sampled_from(list(EstimateSource))))


class DrawnAnemometer:
    def __init__(self, data):
        self.data = data

    async def read(self, t: float) -> WindSample:
        if self.data.draw(st.integers(0, 5)) == 0:
            raise DriveCommError("anemometer: no answer (drawn)")
        speeds = st.one_of(st.floats(0.0, 60.0), wild)
        return WindSample(t, self.data.draw(speeds), self.data.draw(speeds), self.data.draw(speeds))

    async def close(self) -> None:
        pass


class OvercastController(Controller):
    """The real controller, with the sky switch's verdict drawn (DIFFUSE needs hours of
    pyranometer data otherwise)."""

    overcast = False

    async def _sky(self, t: float) -> bool:
        return self.overcast


async def _run(cfg: Config, data, cycles: int) -> tuple[Controller, dict[str, RecordingDrive]]:
    clock = SimClock(T0 + data.draw(st.floats(0.0, 86400.0)))
    drives = {tr.name: RecordingDrive(tr, data) for tr in cfg.trackers}
    anemometer = DrawnAnemometer(data) if cfg.wind is not None else None
    ctl = OvercastController(cfg, drives, DrawnSun(data), clock, anemometer=anemometer)
    bridge = Northbound(ctl, "prop")
    await ctl.start()
    for _ in range(cycles):
        ctl.overcast = data.draw(st.booleans())
        weather = data.draw(st.sampled_from(["none", "wind", "calm", "snow", "hail", "withdraw"]))
        if weather == "wind":
            ctl.safety.wind = WindState(True, True, "wind: drawn gust")
        elif weather == "calm":
            ctl.safety.wind = WindState(False, False)
        elif weather in ("snow", "hail"):
            ctl.safety.request(data.draw(st.sampled_from(["operator", "sunspec", "flag file"])), weather)
        elif weather == "withdraw":
            ctl.safety.requests.clear()
        if data.draw(st.booleans()):
            ctl.set_override(
                data.draw(st.sampled_from([None, 0, 1])),
                data.draw(st.sampled_from(["Automatic", "Manual", "Manual", "Calibrate"])),
                data.draw(st.one_of(st.none(), wild)),
                data.draw(st.one_of(st.none(), wild)),
            )
        if cfg.wind is not None and data.draw(st.booleans()):
            await ctl.poll_weather()  # between cycles, as the scheduler does
        bridge.publish(await ctl.cycle())
        ctl.clock.sleep(data.draw(st.sampled_from([1.0, 60.0, 3600.0, 6 * 3600.0])))
    return ctl, drives


@bounded(100)
@given(plants(), st.data())
def test_no_sequence_of_inputs_sends_a_target_outside_the_limits(cfg, data):
    _ctl, drives = asyncio.run(_run(cfg, data, cycles=6))
    for name, drive in drives.items():
        tracker = drive.tracker
        for targets in drive.targets:
            assert in_limits(tracker, targets), (name, targets, tracker.soft_limits)
        for c in drive.configured:  # what the drive is told to protect itself with
            assert [tuple(x) for x in c["soft_limits"]] == tracker.soft_limits
            assert in_limits(tracker, c["stow_angles"]), (name, c)


SIMPLE = {
    "site": {"latitude": 45.0, "longitude": 7.0},
    "links": [{"name": "l", "kind": "modbus-rtu"}],
    "trackers": [
        {"name": "d", "type": "dual-axis", "link": "l", "device_id": 1, "azimuth_limits": [-20.0, 380.0]},
        {"name": "r", "type": "single-axis", "link": "l", "device_id": 2, "stow": 5.0},
    ],
}


class _Sun(SunSource):
    def __init__(self, az: float, el: float):
        self.az, self.el = az, el

    def estimate(self, t: float, now: float | None = None) -> SunEstimate | None:
        return SunEstimate(t, self.az, self.el)


@pytest.mark.parametrize(
    ("az", "el"), [(math.inf, 30.0), (math.nan, 30.0), (120.0, math.nan), (-math.inf, math.inf)]
)
def test_a_non_finite_sun_estimate_stows_instead_of_crashing_the_cycle(az, el):
    """Found by the property tests: an infinite or NaN azimuth with a plausible elevation
    chose TRACK, and the dual-axis setpoint raised ValueError (math.floor of NaN) out of
    Controller.cycle(), so no drive got a target that cycle (and the loop stopped)."""
    cfg = parse_config(SIMPLE)
    drives = {tr.name: RecordingDrive(tr) for tr in cfg.trackers}
    ctl = Controller(cfg, drives, _Sun(az, el), SimClock(T0))

    async def go():
        await ctl.start()
        return await ctl.cycle()

    recs = asyncio.run(go())
    assert [(r.mode, r.reason) for r in recs] == [("STOW", "no sun estimate")] * 2
    assert drives["d"].targets == [[180.0, 90.0]] and drives["r"].targets == [[5.0]]
    est = SunEstimate(T0, az, el)
    assert sp.tracking(est, cfg.trackers, [None, None]) == [([180.0, 90.0], False), ([5.0], False)]


# -- the pure functions ----------------------------------------------------------------------
@bounded(300)
@given(plants(), st.lists(st.one_of(wild, st.none(), st.just("12")), min_size=1, max_size=2))
def test_clamp_targets_gives_finite_targets_inside_the_limits(cfg, values):
    for tracker in cfg.trackers:
        targets = (values * 2)[: tracker.axes]
        assert in_limits(tracker, clamp_targets(tracker, targets))  # type: ignore[arg-type]


@bounded(200)
@given(plants(), st.sampled_from(list(ControlMode)), wild, wild, st.data())
@example(
    parse_config(
        {
            "site": {"latitude": 45.0, "longitude": 7.0},
            "links": [{"name": "l", "kind": "modbus-rtu"}],
            "trackers": [{"name": "d", "type": "dual-axis", "link": "l", "device_id": 1}],
        }
    ),
    ControlMode.TRACK,
    math.inf,
    30.0,
    None,
)
def test_setpoints_of_any_mode_and_estimate_are_clamped_to_the_limits(cfg, mode, az, el, data):
    trackers = list(cfg.trackers)
    states = [
        None if data is None else data.draw(st.one_of(st.none(), axis_states(t.axes))) for t in trackers
    ]
    est = SunEstimate(T0, az, el)
    for (targets, _backtracking), tracker in zip(sp.for_mode(mode, est, trackers, states), trackers):
        assert in_limits(tracker, clamp_targets(tracker, targets))


@bounded(200)
@given(plants(), st.one_of(st.none(), wild), st.one_of(st.none(), wild), st.data())
def test_a_manual_setpoint_of_any_floats_is_inside_the_limits(cfg, el, az, data):
    for tracker in cfg.trackers:
        state = data.draw(st.one_of(st.none(), axis_states(tracker.axes)))
        # the azimuth wrap accepts 1e-9 deg of rounding; clamp_targets then makes it exact
        manual = sp.manual(tracker, state, el, az)
        assert in_limits(tracker, manual, tol=1e-9) and in_limits(
            tracker, clamp_targets(tracker, list(manual))
        )


@bounded(100)
@given(plants(), st.sampled_from(["wind", "hail", "snow"]))
def test_weather_stow_angles_are_inside_the_limits(cfg, kind):
    safety = SafetyState(cfg.wind, cfg.stow, T0)
    for tracker in cfg.trackers:
        assert in_limits(tracker, safety.angles(tracker, kind))


# -- an override over SunSpec ------------------------------------------------------------------
@bounded(150)
@given(
    plants(),
    st.sampled_from([None, 0, 1]),
    st.integers(-(2**31), 2**31 - 1),
    st.integers(-(2**31), 2**31 - 1),
)
def test_an_override_over_sunspec_is_refused_or_clamped(cfg, tracker, el_raw, az_raw):
    """Any register values written to ElCtl/AzCtl (or the global points) with Ctl = Manual:
    exception 3, or a target inside the limits at the drive."""
    drives = {tr.name: RecordingDrive(tr) for tr in cfg.trackers}
    ctl = Controller(cfg, drives, _FixedSun(), SimClock(T0))
    bridge = Northbound(ctl, "prop")

    async def go() -> None:
        await ctl.start()
        bridge.publish(await ctl.cycle())
        snap = bridge.snapshot()
        table = ControlTable(SunSpecMap(len(cfg.trackers)))
        table.refresh(snap)
        names = ("GlblElCtl", "GlblAzCtl", "GlblCtl") if tracker is None else ("ElCtl", "AzCtl", "Ctl")
        for name, words in zip(names, (_int32(el_raw), _int32(az_raw), [1])):
            try:
                for cmd in table.apply_write(snap, table.map.slot(name, tracker).address, words, "127.0.0.1"):
                    bridge.on_override(cmd)
            except WriteRefused as exc:
                # the azimuth of the row, through the global points, is not its to write
                assert int(exc.code) in (2, 3)
        bridge.apply_pending()
        await ctl.cycle()

    asyncio.run(go())
    for drive in drives.values():
        assert drive.targets and all(in_limits(drive.tracker, t) for t in drive.targets)


def _int32(raw: int) -> list[int]:
    raw &= 0xFFFFFFFF
    return [raw >> 16, raw & 0xFFFF]


class _FixedSun(SunSource):
    def estimate(self, t: float, now: float | None = None) -> SunEstimate | None:
        return SunEstimate(t, 135.0, 40.0)
