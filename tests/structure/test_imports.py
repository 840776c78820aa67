"""The house rules of the code base, checked on the source."""

from __future__ import annotations

import ast

from tests.structure.imports import PACKAGES, ROOT, cycles, graph, module_name, source_files

#: Which top-level packages each layer may import (besides itself).
ALLOWED = {
    "firmware_protocol": set(),
    "controller": {"firmware_protocol"},
    "hil": {"firmware_protocol"},
    "heliotrack": {"firmware_protocol", "controller", "hil", "benchmarks"},
    "benchmarks": {"firmware_protocol", "controller", "hil", "heliotrack"},
}
MAX_LINES = 500
GENERATED = ("firmware_protocol/generated/",)


def test_no_import_cycle_among_the_projects_modules():
    found = cycles(graph())
    assert not found, "import cycles: " + "; ".join(" <-> ".join(c) for c in found)


def test_layers_import_only_what_they_may():
    bad = []
    for module, targets in graph().items():
        layer = module.split(".")[0]
        for target, line in targets.items():
            other = target.split(".")[0]
            if other != layer and other not in ALLOWED[layer]:
                bad.append(f"{module}:{line} imports {target}")
    assert not bad, "\n".join(bad)


def test_no_source_file_over_the_size_limit():
    long = []
    for path in source_files():
        rel = path.relative_to(ROOT).as_posix()
        if rel.startswith(GENERATED):
            continue
        n = len(path.read_text().splitlines())
        if n > MAX_LINES:
            long.append(f"{rel}: {n} lines")
    assert not long, "\n".join(long)


def test_no_private_name_is_imported_across_modules():
    bad = []
    for path in source_files():
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom) and node.module != "__future__":
                base = (node.module or "").split(".")[0]
                if node.level == 0 and base not in PACKAGES:
                    continue  # third-party privates are the libraries' business
                for alias in node.names:
                    if alias.name.startswith("_") and not alias.name.startswith("__"):
                        bad.append(f"{module_name(path)}:{node.lineno} imports {alias.name}")
    assert not bad, "\n".join(bad)
