"""Writing a calibration bundle only when it reads back valid.

A calibration step whose fit failed (a NaN from degenerate input, a residual the schema
refuses) must not leave a bundle that no longer loads: the text is parsed and validated as
the next ``load`` will, and written atomically only then, so a failure loses nothing
already stored.
"""

from __future__ import annotations

import tomllib
from collections.abc import Callable
from pathlib import Path
from typing import Any

from ..atomic import atomic_write
from ..errors import ConfigError


def write_if_valid(path: Path, text: str, validate: Callable[[dict[str, Any], Path], Any]) -> Path:
    """Write ``text`` (a bundle's TOML) to ``path`` if ``validate(doc, path)`` accepts it.

    Raises
    ------
    ConfigError
        Naming the key the result got wrong; the file at ``path`` is unchanged.
    """
    try:
        validate(tomllib.loads(text), path)
    except ConfigError as exc:
        raise ConfigError(
            path,
            exc.key,
            f"{exc.expected} (in this step's result: not written, the file is unchanged)",
            exc.got,
        ) from None
    return atomic_write(path, text)
