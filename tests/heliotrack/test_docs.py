"""Every example in README.md and docs/*.md runs, so none rots.

- ```sh blocks run line by line from a scratch folder holding ``config/`` and ``samples/``
  (as from the top of the repository): ``heliotrack ...`` in-process through the console
  script's ``main`` (globs expanded, ``> FILE`` honoured), ``mkdir -p``, ``cp A B``; any other command
  fails the test until the block says why it cannot run here.
- ```python blocks compile (top-level ``await`` allowed), and every name they import exists.
- ```toml blocks parse.

A block is marked by an HTML comment on the line before it: ``<!-- doctest: skip (why) -->``.
Real-plant commands (``run``, ``check`` on ``plant.toml``; ``<!-- doctest: emulators -->``)
run against a plant of emulators in other processes (``check`` must find every device;
``run`` is stopped by SIGTERM after two cycles and must exit 0).  A block for a real
installation (``sudo``, ``systemctl``, paths under /etc, /var, /opt) cannot run here: its
``heliotrack`` command lines are only parsed.
"""

from __future__ import annotations

import ast
import contextlib
import glob
import importlib
import io
import os
import re
import shlex
import shutil
import signal
import threading
import time
import tomllib
from functools import partial

import pytest

from heliotrack.cli import build_parser, main
from tests.conftest import REPO
from tests.heliotrack.plant_emulators import (
    daytime_site,
    heliotrack,
    plant_toml,
    start_plant,
    wait_for,
)

DOCS = [REPO / "README.md", *sorted((REPO / "docs").glob("*.md"))]
BLOCK = re.compile(
    r"(?:<!--\s*doctest:\s*(?P<mark>[^>]*?)\s*-->[ \t]*\n)?^```(?P<lang>[\w-]*)[^\n]*\n(?P<body>.*?)^```",
    re.S | re.M,
)
SHELL = {"sh", "bash", "shell", "console"}
#: A block for a real machine: system commands, an installation's paths.
DEPLOYMENT = re.compile(r"(^|\s)(sudo|systemctl|journalctl)\s|\s/(etc|var|opt)/", re.M)


def blocks(langs: set[str]) -> list:
    out = []
    for path in DOCS:
        text = path.read_text()
        for m in BLOCK.finditer(text):
            if m["lang"] in langs:
                line = text.count("\n", 0, m.start("body")) + 1
                rel = path.relative_to(REPO)
                out.append(pytest.param(path, line, m["mark"] or "", m["body"], id=f"{rel}:{line}"))
    return out


def commands(body: str) -> list[tuple[int, str]]:
    """Shell lines of a block (continuations joined, comments and blanks dropped)."""
    out, pending, first = [], "", 0
    for i, raw in enumerate(body.splitlines()):
        if not pending:
            first = i
        if raw.rstrip().endswith("\\"):
            pending += raw.rstrip()[:-1] + " "
            continue
        line = (pending + raw).strip()
        pending = ""
        if line and not line.startswith("#"):
            out.append((first, line))
    return out


def run_line(words: list[str], where: str) -> None:
    redirect = None
    if ">" in words:
        i = words.index(">")
        words, redirect = words[:i], words[i + 1]
    if words[0] == "mkdir":
        for w in words[1:]:
            if not w.startswith("-"):
                os.makedirs(w, exist_ok=True)
        return
    if words[0] == "cp" and len(words) == 3:
        shutil.copyfile(words[1], words[2])
        return
    if words[0] != "heliotrack":
        pytest.fail(
            f"{where}: `{words[0]}` cannot run in the doc test: mark the block <!-- doctest: skip (why) -->"
        )
    args = []
    for w in words[1:]:
        args += sorted(glob.glob(w)) if any(c in w for c in "*?[") else [w]
    out = open(redirect, "w") if redirect else io.StringIO()  # noqa: SIM115 - closed below
    try:
        with contextlib.redirect_stdout(out):
            rc = main(args)
    finally:
        out.close()
    assert rc == 0, f"{where}: {' '.join(words)} exited {rc}"


def any_line(lines: list[str], text: str) -> bool:
    return any(text in ln for ln in lines)


def run_on_emulators(lines: list[tuple[int, str]], where: str, folder) -> None:
    """``check`` and ``run`` of a block against a plant of emulators (``plant.toml``: an
    RTU drive on a pty, a TCP drive, a CANopen drive behind an slcan pty): ``check`` must
    find every device; ``run`` runs until its second cycle, then SIGTERM must end it with 0."""
    plant = start_plant()
    try:
        plant_toml(folder / "plant.toml", plant, daytime_site(time.time()), period=1.0, heartbeat=3.0)
        for offset, text in lines:
            words = shlex.split(text, comments=True)
            assert words[:1] == ["heliotrack"], f"{where}+{offset}: {text}"
            if words[1] != "run":
                run_line(words, f"{where}+{offset}")
                continue
            proc = heliotrack(*words[1:], cwd=folder)
            seen: list[str] = []
            threading.Thread(target=seen.extend, args=(proc.stderr,), daemon=True).start()
            try:
                assert wait_for(partial(any_line, seen, "cycle 2"), 60.0, 0.1), seen[-20:]
                proc.send_signal(signal.SIGTERM)
                assert proc.wait(30) == 0, "".join(seen[-20:])
            finally:
                if proc.poll() is None:
                    proc.kill()
                    proc.wait()
    finally:
        plant.stop()


def syntax_only(lines: list[tuple[int, str]], where: str) -> None:
    """Commands that can only run on a real installation: their options must still exist."""
    parser = build_parser()
    for offset, text in lines:
        words = shlex.split(text, comments=True)
        if words[0] != "heliotrack" or "[" in text:
            continue
        try:
            with contextlib.redirect_stderr(io.StringIO()):
                parser.parse_args(words[1:])
        except SystemExit:
            pytest.fail(f"{where}+{offset}: {text}: the command line parser refuses it")


@pytest.mark.parametrize(("path", "line", "mark", "body"), blocks(SHELL))
def test_shell_example_runs(path, line, mark, body, tmp_path, monkeypatch):
    where = f"{path.relative_to(REPO)}:{line}"
    if mark.startswith("skip"):
        pytest.skip(f"{where}: {mark}")
    lines = commands(body)
    if DEPLOYMENT.search(body):
        syntax_only(lines, where)
        pytest.skip(f"{where}: the commands of a real installation (their options were checked)")
    for name in ("config", "samples"):
        (tmp_path / name).symlink_to(REPO / name)
    monkeypatch.chdir(tmp_path)
    if mark == "emulators" or any(
        shlex.split(text, comments=True)[1:2] in (["run"], ["check"]) for _, text in lines
    ):
        run_on_emulators(lines, where, tmp_path)
        return
    assert not mark, f"{where}: unknown doctest mark {mark!r}"
    for offset, text in lines:
        run_line(shlex.split(text, comments=True), f"{where}+{offset}")


@pytest.mark.parametrize(("path", "line", "mark", "body"), blocks({"python"}))
def test_python_example_compiles_and_its_imports_exist(path, line, mark, body):
    where = f"{path.relative_to(REPO)}:{line}"
    if mark.startswith("skip"):
        pytest.skip(f"{where}: {mark}")
    tree = compile(body, where, "exec", flags=ast.PyCF_ONLY_AST | ast.PyCF_ALLOW_TOP_LEVEL_AWAIT)
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            for alias in node.names:
                importlib.import_module(alias.name)
        elif isinstance(node, ast.ImportFrom) and node.module:
            module = importlib.import_module(node.module)
            for alias in node.names:
                assert hasattr(module, alias.name), f"{where}: {node.module} has no {alias.name}"


@pytest.mark.parametrize(("path", "line", "mark", "body"), blocks({"toml"}))
def test_toml_example_parses(path, line, mark, body):
    if mark.startswith("skip"):
        pytest.skip(mark)
    tomllib.loads(body)


def test_every_workflow_has_an_example():
    text = (REPO / "README.md").read_text()
    for command in (
        "simulate",
        "check",
        "run",
        "hil record",
        "replay",
        "report",
        "calibrate",
        "estimate",
        "sunpath",
        "classify",
        "bench",
    ):
        assert re.search(rf"^heliotrack {command} ", text, re.M), command
