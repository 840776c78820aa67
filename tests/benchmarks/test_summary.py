"""`heliotrack bench` summary: headline rows from every committed result, a miss exits 1."""

import json
import shutil

from benchmarks import BENCHMARKS, RESULTS_DIR
from benchmarks.summary import headlines, load_results
from heliotrack.cli import main


def test_every_committed_result_gives_headline_rows():
    for name, rec in load_results(list(BENCHMARKS)).items():
        if rec is None:
            continue
        rows = headlines(name, rec["result"])
        assert rows, name
        assert not any(r.figure == "result file" for r in rows), (name, rows)


def test_summary_marks_a_miss_and_the_command_exits_1(tmp_path, capsys):
    shutil.copy(RESULTS_DIR / "persistence.json", tmp_path / "persistence.json")
    assert main(["bench", "persistence", "--summary-only", "--results-dir", str(tmp_path)]) == 0
    rec = json.loads((tmp_path / "persistence.json").read_text())
    rec["result"]["corruptions"] = 2
    (tmp_path / "persistence.json").write_text(json.dumps(rec))
    assert main(["bench", "persistence", "--summary-only", "--results-dir", str(tmp_path)]) == 1
    assert "persistence: corruptions = 2 (target 0)" in capsys.readouterr().err
    md = (tmp_path / "summary.md").read_text()
    assert "| persistence" in md and "**miss**" in md and "(not run)" in md


def test_a_size_other_than_the_default_is_its_own_result(tmp_path, capsys):
    """An audit's case: --kills 3 overwrote the 1000-kill persistence.json; --kills 0 passed
    vacuously; a --results-dir that was a file failed after the run."""
    import pytest

    assert main(["bench", "persistence", "--kills", "3", "--results-dir", str(tmp_path)]) == 0
    assert sorted(p.name for p in tmp_path.glob("persistence*.json")) == ["persistence-kills3.json"]
    for bad in ("0", "-5"):
        with pytest.raises(SystemExit):
            main(["bench", "persistence", "--kills", bad, "--results-dir", str(tmp_path)])
        assert "expected an integer in [1, 100000]" in capsys.readouterr().err
    blocker = tmp_path / "afile"
    blocker.write_text("x")
    assert main(["bench", "persistence", "--kills", "3", "--results-dir", str(blocker)]) == 2
    assert "--results-dir: cannot write to" in capsys.readouterr().err


def test_a_quick_run_is_named_by_its_own_size_and_summarised(tmp_path, capsys):
    """--quick --kills 20 (the quick size) had been named persistence-kills20-quick.json and
    --quick --kills 1000 persistence-quick.json; quick results never reached summary.md."""
    argv = ["bench", "persistence", "--quick", "--results-dir", str(tmp_path)]
    assert main([*argv, "--kills", "20"]) == 0
    assert main([*argv, "--kills", "3"]) == 0
    names = sorted(p.name for p in tmp_path.glob("persistence*.json"))
    assert names == ["persistence-kills3-quick.json", "persistence-quick.json"]
    assert main(["bench", "--summary-only", "--results-dir", str(tmp_path)]) in (0, 1)
    md = (tmp_path / "summary.md").read_text()
    assert "| persistence (" in md and ", quick)" in md
