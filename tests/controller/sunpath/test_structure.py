"""The sun-path package stays split by responsibility: short modules, no private imports
across modules, and the public names callers use still importable where they were."""

import ast
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[3]
PACKAGE = ROOT / "controller" / "sunpath"
MINE = [
    *PACKAGE.glob("*.py"),
    *ROOT.glob("benchmarks/sunpath*.py"),
    ROOT / "heliotrack" / "commands" / "sunpath.py",
]


@pytest.mark.parametrize("path", MINE, ids=lambda p: p.name)
def test_no_source_file_over_500_lines(path):
    assert len(path.read_text().splitlines()) <= 500


@pytest.mark.parametrize("path", sorted(PACKAGE.glob("*.py")), ids=lambda p: p.name)
def test_no_private_name_imported_across_modules(path):
    tree = ast.parse(path.read_text())
    for node in ast.walk(tree):
        if isinstance(node, ast.ImportFrom):
            private = [a.name for a in node.names if a.name.startswith("_")]
            assert not private, f"{path.name} imports {private} from {node.module}"


def test_public_names_still_importable_from_kalman():
    from controller.sunpath import initial_fit, kalman, kalman_config, orbit, persistence

    for name in kalman.__all__:
        assert hasattr(kalman, name), name
    assert kalman.orbit_advance_deg is orbit.orbit_advance_deg
    assert kalman.KalmanConfig is kalman_config.KalmanConfig
    assert callable(initial_fit.initial_fit) and callable(persistence.kalman_to_dict)
