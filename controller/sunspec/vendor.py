"""heliotrack's vendor model 64601 "weather stow": what model 601 cannot say.

Model 601 has no weather point: its alarms are SetPoint, ObsEl and ObsAz.  SCADA still
needs to see a wind stow (and the gust that caused it), a lost anemometer, a snow or hail
stow, and to ask for a snow or hail stow itself.  SunSpec reserves model ids 64000-65535
for vendors; this one follows model 601 in the map (``docs/sunspec.md``).

The definition is pysunspec2's JSON format, so the server builds its map from it exactly as
it does from pysunspec2's model files, and a SCADA client built on pysunspec2 decodes it
once the file is on its model path (:func:`write_model_json`).  A client without the file
still scans the device: pysunspec2 records the unknown model and goes on to the next.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

WEATHER_MODEL_ID = 64601
WIND_SF = -2  # wind speeds in 0.01 m/s, like the anemometer's registers

#: ``Stow`` values: the weather stow in force (highest priority first, as the controller).
STOW_KINDS = ("NONE", "WIND", "HAIL", "SNOW")
#: ``StowReq`` values: SCADA's own snow or hail stow request (``SafetyState`` source
#: "sunspec"); 0 withdraws it.
STOW_REQUESTS = ("NONE", "SNOW", "HAIL")
#: ``Alm`` bits.
ALARM_BITS = ("WindStow", "AnemometerLost", "HailStow", "SnowStow", "StowRequested")


def _point(name: str, type_: str, size: int, label: str, desc: str, **extra: Any) -> dict[str, Any]:
    return {"name": name, "type": type_, "size": size, "label": label, "desc": desc, **extra}


def _symbols(names: tuple[str, ...]) -> list[dict[str, Any]]:
    return [{"name": n, "value": i} for i, n in enumerate(names)]


def weather_model_definition() -> dict[str, Any]:
    """The model's definition in pysunspec2's JSON form (a fresh dict each call)."""
    wind = {"sf": "Wind_SF", "units": "m/s"}
    points = [
        _point(
            "ID",
            "uint16",
            1,
            "Model ID",
            "Model identifier",
            value=WEATHER_MODEL_ID,
            mandatory="M",
            static="S",
        ),
        _point("L", "uint16", 1, "Model Length", "Model length", mandatory="M", static="S"),
        _point(
            "Stow",
            "enum16",
            1,
            "Weather Stow",
            "The weather stow in force: wind (incl. a lost anemometer), then hail, then snow",
            mandatory="M",
            symbols=_symbols(STOW_KINDS),
        ),
        _point(
            "Alm",
            "bitfield32",
            2,
            "Weather Alarms",
            "Weather alarms; a lost anemometer alarms even when it is configured not to stow",
            mandatory="M",
            symbols=_symbols(ALARM_BITS),
        ),
        _point("WindSpd", "uint16", 1, "Wind Speed", "Last 1-s mean wind speed", **wind),
        _point("WindGst", "uint16", 1, "Wind Gust", "Highest 3-s mean of the last 30 s (WMO gust)", **wind),
        _point("WindAvg", "uint16", 1, "Wind 10-min Mean", "10-min mean wind speed", **wind),
        _point(
            "StowReq",
            "enum16",
            1,
            "SCADA Stow Request",
            "Snow or hail stow asked by SCADA (0 withdraws it); other sources (operator, "
            "flag file) are not shown here",
            access="RW",
            mandatory="M",
            symbols=_symbols(STOW_REQUESTS),
        ),
        _point("Rsn", "string", 16, "Stow Reason", "Why the weather stow is in force (UTF-8, 32 bytes)"),
        _point(
            "Wind_SF", "sunssf", 1, "Wind SF", "Scale factor of the wind speeds", mandatory="M", static="S"
        ),
    ]
    return {
        "id": WEATHER_MODEL_ID,
        "group": {
            "name": "heliotrack_weather",
            "type": "group",
            "label": "heliotrack Weather Stow",
            "desc": "Weather stow, wind and SCADA stow requests of a heliotrack tracker controller",
            "points": points,
        },
    }


def write_model_json(folder: str | Path) -> Path:
    """Write ``model_64601.json`` into ``folder`` (for a pysunspec2 client's model path::

    import sunspec2.device as sd
    sd.set_model_defs_path([folder, *sd.get_model_defs_path()])
    """
    path = Path(folder) / f"model_{WEATHER_MODEL_ID}.json"
    path.write_text(json.dumps(weather_model_definition(), indent=2) + "\n", encoding="utf-8")
    return path
