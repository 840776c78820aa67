"""The configuration reference (``docs/config.md``), generated from the schema classes."""

from __future__ import annotations

from controller.calibration.bundle import CalibrationBundle
from controller.schema import markdown
from controller.sky.settings import SkySettings

from .resources import writable_home
from .scenario import ScenarioConfig

DOCS_PATH = writable_home("docs/config.md")

DOCUMENTS: dict[str, tuple[type, str]] = {
    "Plant and scenario files": (
        ScenarioConfig,
        "`heliotrack run`, `check` and `simulate` read these (`config/*.toml`).  The `[hil]` "
        "table describes the emulated world and belongs to scenario files only: `simulate` "
        "reads it, a plant file for `run` must not have it.  Link kinds are backends of the "
        "drive-link registry (`controller/drives/registry.py`); each kind has its own keys.",
    ),
    "Hotspot-sensor calibration bundle": (
        CalibrationBundle,
        "`heliotrack estimate --calib`, `[hotspot] calibration`; written by "
        "`heliotrack calibrate` (see docs/hotspot.md).",
    ),
    "Sky settings": (
        SkySettings,
        "`heliotrack classify --settings FILE`: the day-type classifier (see docs/skytype.md).",
    ),
}


def reference() -> str:
    """The whole reference, as Markdown."""
    return markdown(DOCUMENTS)
