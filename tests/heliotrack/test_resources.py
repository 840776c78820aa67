"""Where the project writes its own files: the checkout, or the working directory of an
installed wheel (an audit found `config docs` and `bench` writing into site-packages)."""

import importlib.util
import shutil

from heliotrack.resources import writable_home
from tests.conftest import REPO


def test_a_checkout_writes_in_itself():
    assert writable_home("docs/config.md") == REPO / "docs" / "config.md"


def test_an_installed_package_writes_under_the_working_directory(tmp_path, monkeypatch):
    site = tmp_path / "site-packages" / "heliotrack"
    site.mkdir(parents=True)
    shutil.copy(REPO / "heliotrack" / "resources.py", site / "resources.py")
    spec = importlib.util.spec_from_file_location("installed_resources", site / "resources.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    work = tmp_path / "work"
    work.mkdir()
    monkeypatch.chdir(work)
    assert mod.writable_home("benchmarks/results") == work / "benchmarks" / "results"
