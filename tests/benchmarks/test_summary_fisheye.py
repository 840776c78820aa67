"""Headline rows of the fisheye benchmark (benchmarks.summary_fisheye)."""

from benchmarks.summary_fisheye import UNDECLARED, other_looks_worst


def _looks(**rms):
    return {f"other renderer, {k}": {"error": {"rms_deg": v}} for k, v in rms.items()}


def test_the_worst_other_look_is_named_and_judged_at_each_size():
    other = {
        "clear": {**_looks(wide=0.031, sky=0.012), UNDECLARED: {"error": {"rms_deg": 0.5}}},
        "clear_1280x960": _looks(wide=0.053, bloom=0.021),
    }
    row = other_looks_worst(other)
    assert row.value == "0.031 / 0.053 deg" and row.paper == "wide; wide" and row.ok is False
    other["clear"] = _looks(sky=0.02)
    other["clear_1280x960"] = _looks(main=0.012)
    assert other_looks_worst(other).ok is True


def test_a_look_with_no_frame_found_is_a_miss():
    row = other_looks_worst({"clear": _looks(lost=None), "clear_1280x960": _looks(main=0.01)})
    assert row.ok is False and row.paper.startswith("lost")


def test_the_other_renderers_speed_is_a_row_of_its_own_held_to_200():
    import json
    from pathlib import Path

    from benchmarks.summary_fisheye import fisheye

    r = json.loads((Path(__file__).parents[2] / "benchmarks/results/fisheye.json").read_text())["result"]
    others = r["fps"]["640x480, other renderers"]
    rows = [h for h in fisheye(r) if "second / third renderer" in h.figure]
    assert len(rows) == 1
    want = min(v["fps"] for v in others.values()) >= 200
    assert rows[0].ok is want and rows[0].target == ">= 200"
