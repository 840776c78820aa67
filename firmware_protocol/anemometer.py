"""Register map of the Modbus anemometer the controller reads (and the HIL emulates).

Modelled on smart ultrasonic and cup anemometers with a Modbus RTU interface (Lufft
Ventus, Thies, Gill): input registers read with function code 4, 0-based addresses, one
16-bit word each.  The instrument samples at 4 Hz and computes the WMO gust (the highest
3-s running mean) itself, which a controller polling every few seconds could not; it holds
the highest gust of the last 30 s so that no gust falls between two polls.  A sample
counter lets the controller tell a frozen sensor from a steady wind.
"""

from __future__ import annotations

from .registers import Register

ANEMOMETER_DEVICE_TYPE = 0x0A4E  # informative, "AN"
#: The instrument's gust register holds the highest 3-s mean of this window, s.
GUST_HOLD_S = 30.0
#: Sample rate of the instrument, Hz.
SAMPLE_HZ = 4

ANEMOMETER_REGISTERS: tuple[Register, ...] = (
    Register("ANE_DEVICE_TYPE", 0, "uint16", 1, "", "R", "Instrument type code."),
    Register("ANE_SPEED", 1, "uint16", 0.01, "m/s", "R", "Wind speed, 1-s mean."),
    Register(
        "ANE_GUST",
        2,
        "uint16",
        0.01,
        "m/s",
        "R",
        "Highest 3-s running mean speed of the last 30 s (WMO gust).",
    ),
    Register("ANE_MEAN_10MIN", 3, "uint16", 0.01, "m/s", "R", "10-min mean speed."),
    Register(
        "ANE_DIRECTION",
        4,
        "uint16",
        0.1,
        "deg",
        "R",
        "Wind direction, clockwise from north, where it blows from.",
    ),
    Register(
        "ANE_SAMPLE_COUNT",
        5,
        "uint16",
        1,
        "",
        "R",
        "Samples taken since power-up, modulo 65536 (stops when the sensor freezes).",
    ),
    Register(
        "ANE_STATUS",
        6,
        "uint16",
        1,
        "",
        "R",
        "0 = ok; bit 0 sensor fault, bit 1 out of range, bit 2 heater on.",
    ),
)

ANEMOMETER_SPACE = 16
ANE = {r.name: r for r in ANEMOMETER_REGISTERS}
#: Status bits that make a sample unusable.
ANE_STATUS_BAD = 0b011
