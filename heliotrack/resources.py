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


def writable_home(relative: str) -> Path:
    """Where ``relative`` (a folder or file the project writes: ``docs/config.md``,
    ``benchmarks/results``) goes: in the source checkout this package runs from, or, when
    it runs from an installed wheel, under the working directory (site-packages is no place
    to write, and a deployed venv may be read-only)."""
    root = Path(__file__).resolve().parents[1]
    if (root / "pyproject.toml").is_file():
        return root / relative
    return Path.cwd() / relative
