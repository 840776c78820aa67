"""The emulated world's fault kinds: their names, default durations and magnitudes, and
the bounds a scenario's magnitudes must keep (docs/faults.md)."""

from __future__ import annotations

from typing import Literal, get_args

from controller.schema import Where

#: Faults in one axis of a drive (the HIL's ``AxisModel``).
AxisFault = Literal[
    "drive_stall", "drive_overtemperature", "drive_overcurrent", "limit_switch", "encoder_glitch"
]
#: Faults that hit a tracker's drive.
TrackerFault = Literal[AxisFault, "emulator_restart"]
#: Faults that last a while: switched on and off on the simulated clock.
TimedFault = Literal[
    TrackerFault,
    "can_error_passive",
    "can_bus_off",
    "pyranometer_out_of_range",
    "pyranometer_frozen",
    "pyranometer_nan",
    "anemometer_out_of_range",
    "anemometer_frozen",
    "anemometer_nan",
    "camera_black",
    "camera_saturated",
    "camera_truncated",
    "camera_wrong_size",
    "camera_missing",
    "wall_clock_step",
]
#: Faults on single Modbus replies (a scheduled one hits every reply of its target).
WireFault = Literal[
    "modbus_timeout", "crc_error", "garbled_reply", "split_reply", "late_reply", "wrong_id_reply"
]
#: Any fault a scheduled event may be.
EventFault = Literal[TimedFault, WireFault]
AXIS_FAULTS: tuple[str, ...] = get_args(AxisFault)
TRACKER_FAULTS: tuple[str, ...] = get_args(TrackerFault)
TIMED_FAULTS: tuple[str, ...] = get_args(TimedFault)  # nested Literals come out flat
WIRE_FAULTS: tuple[str, ...] = get_args(WireFault)
#: Every fault kind, as counted in summary.json.
FAULT_KINDS: tuple[str, ...] = (*WIRE_FAULTS, "can_frame_lost", *TIMED_FAULTS)

#: Default (duration range s, magnitude range) of each timed fault; the magnitude is the
#: step of the wall clock (s, either sign), the encoder's error (deg, either sign), or the
#: out-of-range reading (W/m2, m/s), and means nothing for the others.
FAULT_DEFAULTS: dict[str, tuple[tuple[float, float], tuple[float, float]]] = {
    "drive_stall": ((30.0, 300.0), (0.0, 0.0)),
    "drive_overtemperature": ((60.0, 900.0), (0.0, 0.0)),
    "drive_overcurrent": ((30.0, 600.0), (0.0, 0.0)),
    "limit_switch": ((10.0, 120.0), (0.0, 0.0)),
    "encoder_glitch": ((1.0, 10.0), (0.5, 3.0)),
    "emulator_restart": ((5.0, 120.0), (0.0, 0.0)),
    "can_error_passive": ((10.0, 120.0), (0.0, 0.0)),
    "can_bus_off": ((5.0, 60.0), (0.0, 0.0)),
    "pyranometer_out_of_range": ((60.0, 1800.0), (1700.0, 3000.0)),
    "pyranometer_frozen": ((600.0, 7200.0), (0.0, 0.0)),
    "pyranometer_nan": ((60.0, 1800.0), (0.0, 0.0)),
    "anemometer_out_of_range": ((30.0, 600.0), (80.0, 200.0)),
    "anemometer_frozen": ((30.0, 900.0), (0.0, 0.0)),
    "anemometer_nan": ((30.0, 600.0), (0.0, 0.0)),
    "camera_black": ((60.0, 1800.0), (0.0, 0.0)),
    "camera_saturated": ((60.0, 1800.0), (0.0, 0.0)),
    "camera_truncated": ((60.0, 1800.0), (0.0, 0.0)),
    "camera_wrong_size": ((60.0, 1800.0), (0.0, 0.0)),
    "camera_missing": ((60.0, 1800.0), (0.0, 0.0)),
    "wall_clock_step": ((60.0, 7200.0), (30.0, 3600.0)),
}

#: The largest magnitude of each fault that has one, either sign: a clock step of a year, a
#: glitch of a turn, a reading a register can hold (a wire fault has none).
MAGNITUDE_BOUNDS: dict[str, float] = {
    "encoder_glitch": 360.0,
    "pyranometer_out_of_range": 32767.0,  # an int16 register, W/m2
    "anemometer_out_of_range": 655.0,  # a uint16 register in 0.01 m/s
    "wall_clock_step": 366 * 86400.0,
}


def check_magnitude(at: Where, kind: str, values: tuple[float, ...]) -> None:
    bound = MAGNITUDE_BOUNDS.get(kind)
    if bound is not None and any(abs(v) > bound for v in values):
        raise at.error(
            f"a {kind} magnitude within +-{bound:g}", list(values) if len(values) > 1 else values[0]
        )
