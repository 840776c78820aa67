"""Files shipped inside the package: the example scenarios and calibration bundles.

``config/`` stays at the top of the repository; ``heliotrack/data/config`` points to it
(a symbolic link), so the wheel carries the same files as package data without a second
copy in the tree.  Read them through :func:`bundled_config`, which works from a checkout,
an editable install and a plain ``pip install .`` alike.
"""

from __future__ import annotations

from importlib import resources
from pathlib import Path


def bundled_config(name: str = "hil-default.toml") -> Path:
    """The path of a shipped configuration file (``config/<name>`` in the repository)."""
    return Path(str(resources.files("heliotrack") / "data" / "config" / name))
