"""TOML text of the calibration bundles: values, keys, paths and the ``[camera]`` section.

Both bundles (:mod:`.bundle`, the hotspot sensor's; :mod:`.fisheye_bundle`, the sky
camera's) write their files through these, so that a note's key or a path with a character
TOML must escape reads back as it was written in either.
"""

from __future__ import annotations

import datetime as dt
import re
from pathlib import Path
from typing import Any

import numpy as np

from .camera import CameraCal

_BARE_KEY = re.compile(r"[A-Za-z0-9_-]+")


def toml_string(s: str) -> str:
    """A TOML basic string: quotes, backslashes and control characters escaped."""
    out = ['"']
    for ch in s:
        if ch in '"\\':
            out.append("\\" + ch)
        elif ord(ch) < 0x20 or ord(ch) == 0x7F:
            out.append(f"\\u{ord(ch):04x}")
        else:
            out.append(ch)
    return "".join(out) + '"'


def toml_key(k: str) -> str:
    """``k`` bare where TOML allows it, else quoted."""
    return k if _BARE_KEY.fullmatch(k) else toml_string(k)


def toml_value(v: Any) -> str:
    """A TOML value (anything a loaded bundle holds, ``[notes]`` included)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, (int, np.integer)):
        return str(int(v))
    if isinstance(v, (float, np.floating)):
        return repr(float(v))
    if isinstance(v, (str, Path)):
        return toml_string(str(v))
    if isinstance(v, (dt.datetime, dt.date, dt.time)):
        return v.isoformat()
    if isinstance(v, (list, tuple, np.ndarray)):
        return "[" + ", ".join(toml_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{toml_key(str(k))} = {toml_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def relative_path(p: str | Path, folder: Path | None) -> str:
    """``p`` relative to ``folder`` when inside it (the bundle's own folder, against which a
    loaded bundle resolves it), else as given."""
    if folder is not None:
        try:
            return str(Path(p).resolve().relative_to(Path(folder).resolve()))
        except ValueError:
            pass
    return str(p)


def camera_section(c: CameraCal, model: str | None = None) -> list[str]:
    """The lines of a ``[camera]`` section (a blank line first); ``model`` written when given."""
    out = ["", "[camera]"] + ([f"model = {toml_value(model)}"] if model is not None else [])
    out += [
        f"width = {c.width}",
        f"height = {c.height}",
        f"fx = {toml_value(c.fx)}",
        f"fy = {toml_value(c.fy)}",
        f"cx = {toml_value(c.cx)}",
        f"cy = {toml_value(c.cy)}",
        f"dist = {toml_value(list(c.dist))}",
    ]
    if c.rms_px is not None:
        out.append(f"rms_px = {toml_value(c.rms_px)}")
    return out


def notes_section(notes: dict[str, Any]) -> list[str]:
    """The lines of a ``[notes]`` section (a blank line first), or none for no notes."""
    if not notes:
        return []
    return ["", "[notes]"] + [f"{toml_key(str(k))} = {toml_value(v)}" for k, v in notes.items()]
