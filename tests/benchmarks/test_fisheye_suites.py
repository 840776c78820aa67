from types import SimpleNamespace

from benchmarks.fisheye_suites import frames_per_second, frames_per_second_interleaved


class _Counting:
    """An estimator that records the order of its passes and finds every other frame."""

    def __init__(self, name, log):
        self.name, self.log = name, log

    def reset_sequence(self):
        self.log.append(self.name)

    def estimate_image(self, img, t):
        return SimpleNamespace(found=bool(img % 2))


def test_interleaved_timing_takes_the_runs_passes_in_turn():
    log: list[str] = []
    runs = {
        k: (lambda k=k: _Counting(k, log), list(range(n)), [0.0] * n)
        for k, n in (("a", 4), ("b", 5), ("c", 6))
    }
    out = frames_per_second_interleaved(runs, repeats=4)
    # each round times every run once, and each run leads a round in turn
    assert [sorted(log[i : i + 3]) for i in range(0, 12, 3)] == [["a", "b", "c"]] * 4
    assert [log[i] for i in range(0, 12, 3)] == ["a", "b", "c", "a"]
    assert {k: (v["frames"], v["found"], v["repeats"]) for k, v in out.items()} == {
        "a": (4, 2, 4),
        "b": (5, 2, 4),
        "c": (6, 3, 4),
    }
    assert all(v["fps"] > 0 for v in out.values())


def test_one_run_is_timed_alone():
    log: list[str] = []
    out = frames_per_second(lambda: _Counting("a", log), [1, 2, 3], [0.0] * 3, repeats=3)
    assert log == ["a"] * 3 and out["found"] == 2 and out["repeats"] == 3
