"""The SQLite store: versions, history rotation, schema checks, unusable files kept aside."""

import sqlite3

import pytest

from controller.store import SCHEMA_VERSION, Store, StoreError, open_store_or_none


def test_state_versions_and_round_trip(tmp_path):
    with Store(tmp_path / "s.sqlite") as st:
        assert st.get_state("sunpath") is None
        assert st.put_state("sunpath", {"lat": 32.5}, now=100.0) == 1
        assert st.put_state("sunpath", {"lat": 32.4}, now=200.0) == 2
        rec = st.get_state("sunpath")
        assert (rec.version, rec.updated, rec.body) == (2, 200.0, {"lat": 32.4})
        assert st.schema_version == SCHEMA_VERSION
    with Store(tmp_path / "s.sqlite") as st:  # reopened: still there
        assert st.get_state("sunpath").version == 2


def test_nan_is_refused_not_stored(tmp_path):
    with Store(tmp_path / "s.sqlite") as st:
        st.put_state("x", {"a": 1})
        with pytest.raises(ValueError):
            st.put_state("x", {"a": float("nan")})
        assert st.get_state("x").body == {"a": 1}  # the good version is untouched


def test_history_is_rotated_by_age(tmp_path):
    with Store(tmp_path / "s.sqlite") as st:
        st.add_observations([(t, "hotspot", 100.0, 30.0, 0.05, True) for t in (0.0, 50.0, 100.0)])
        st.add_setpoints([(t, "row-1", "TRACK", "observed", [10.0], [9.99], "") for t in (0.0, 100.0)])
        assert st.rotate(60.0, now=100.0) == 2
        assert [r[0] for r in st.history("observations")] == [50.0, 100.0]
        assert [r[0] for r in st.history("setpoints")] == [100.0]


def test_a_file_that_is_not_a_store_is_an_error_and_kept_aside(tmp_path):
    bad = tmp_path / "s.sqlite"
    bad.write_bytes(b"this is not SQLite at all" * 100)
    with pytest.raises(StoreError, match=r"s.sqlite: not a usable heliotrack store"):
        Store(bad)
    warnings = []
    st = open_store_or_none(bad, warnings.append)
    assert st is not None and st.get_state("sunpath") is None
    st.close()
    kept = [p for p in tmp_path.iterdir() if ".unusable-" in p.name]
    assert len(kept) == 1 and kept[0].read_bytes().startswith(b"this is not SQLite")
    assert len(warnings) == 2 and "kept the unusable store" in warnings[1]


def test_a_foreign_sqlite_file_and_a_newer_schema_are_refused(tmp_path):
    other = tmp_path / "other.sqlite"
    with sqlite3.connect(other) as db:
        db.execute("CREATE TABLE t (x)")
    with pytest.raises(StoreError, match="not a heliotrack store"):
        Store(other)
    newer = tmp_path / "newer.sqlite"
    Store(newer).close()
    with sqlite3.connect(newer) as db:
        db.execute(f"PRAGMA user_version={SCHEMA_VERSION + 1}")
    warnings = []
    assert open_store_or_none(newer, warnings.append) is None
    assert "upgrade heliotrack" in warnings[0] and newer.exists()  # left as it is


def test_killed_writers_never_corrupt_the_store():
    """A reduced form of `heliotrack bench persistence` (1000 kills there)."""
    from benchmarks.persistence import run

    res = run(kills=15)
    assert res["corruptions"] == 0 and res["at_last_commit"] == 15, res
