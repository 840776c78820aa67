"""A plain `pip install .` must be able to run `simulate`: the wheel carries the default
scenarios and calibration bundles (config/) as package data, through the link
heliotrack/data/config -> config/.  `make test` builds the wheel, installs it in a
throwaway venv and simulates an hour from it (`make wheel-test`); these are the quick
checks of the same promise."""

import fnmatch
import subprocess
import tomllib

from heliotrack.resources import bundled_config
from tests.conftest import REPO


def test_package_data_covers_every_file_of_config():
    patterns = tomllib.loads((REPO / "pyproject.toml").read_text())["tool"]["setuptools"]["package-data"]
    shipped = patterns["heliotrack"]
    try:  # the tracked files; an unpacked archive (no git) holds only those
        listed = subprocess.run(["git", "ls-files", "config"], cwd=REPO, capture_output=True, text=True)
    except FileNotFoundError:
        listed = None
    if listed is not None and listed.returncode == 0:
        files = listed.stdout.split()
    else:
        files = [p.relative_to(REPO).as_posix() for p in (REPO / "config").rglob("*") if p.is_file()]
    assert "config/hil-default.toml" in files and "config/calibration/recommended.toml" in files
    for name in files:
        inside = f"data/{name}"
        assert any(
            fnmatch.fnmatch(inside, p) and "/" not in inside[len(p.rsplit("/", 1)[0]) + 1 :] for p in shipped
        ), name
        assert (REPO / "heliotrack" / inside).is_file(), name


def test_the_link_is_the_only_copy_of_config():
    link = REPO / "heliotrack" / "data" / "config"
    assert link.is_symlink() and link.resolve() == (REPO / "config").resolve()


def test_the_default_config_resolves_through_the_package():
    path = bundled_config("hil-default.toml")
    assert path.is_file() and path.resolve() == (REPO / "config" / "hil-default.toml").resolve()
    assert (bundled_config("calibration") / "recommended.toml").is_file()
