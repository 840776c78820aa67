"""Register map of the Modbus pyranometer the controller reads (and the HIL emulates).

Modelled on the common smart-pyranometer layout (Kipp & Zonen SMP series): input
registers read with function code 4, 0-based addresses, one 16-bit word each.  A real
instrument with another map needs only another table here.
"""

from __future__ import annotations

from .registers import Register

PYRANOMETER_DEVICE_TYPE = 0x0259  # informative, "601"

PYRANOMETER_REGISTERS: tuple[Register, ...] = (
    Register("PYR_DEVICE_TYPE", 0, "uint16", 1, "", "R", "Instrument type code."),
    Register("PYR_IRRADIANCE", 5, "int16", 1, "W/m2", "R", "Global irradiance, temperature compensated."),
    Register("PYR_IRRADIANCE_RAW", 6, "int16", 1, "W/m2", "R", "Uncompensated irradiance."),
    Register("PYR_BODY_TEMPERATURE", 8, "int16", 0.1, "degC", "R", "Body temperature."),
    Register(
        "PYR_STATUS",
        27,
        "uint16",
        1,
        "",
        "R",
        "0 = ok; bit 0 sensor fault, bit 1 out of range, bit 2 heater on.",
    ),
)

PYRANOMETER_SPACE = 32
PYR = {r.name: r for r in PYRANOMETER_REGISTERS}
