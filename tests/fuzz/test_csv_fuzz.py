"""Fuzzing the data-file readers (issue 13): irradiance records (``controller.sky.io``) and
sun observations (``controller.sunpath.io``).  Arbitrary bytes and arbitrary CSV or JSON-
lines text give an InputError naming the file, or records that hold what the readers
promise (finite, plausible times and values); never another exception."""

from __future__ import annotations

import json
import math
from pathlib import Path

import numpy as np
from hypothesis import example, given
from hypothesis import strategies as st

from controller.errors import InputError
from controller.sky.io import MAX_IRRADIANCE, MIN_IRRADIANCE, TIME_RANGE, read_records
from controller.sunpath.io import read_observations

from .strategies import bounded, scratch_dir

_DIR = scratch_dir("heliotrack-fuzz-csv-")

cells = st.one_of(
    st.text(max_size=12),
    st.integers(min_value=-(10**12), max_value=10**12).map(str),
    st.floats(allow_nan=True, allow_infinity=True).map(repr),
    st.floats(min_value=-50, max_value=2100).map(lambda x: f"{x:.1f}"),
    st.datetimes().map(lambda t: t.isoformat() + "Z"),
    st.datetimes().map(lambda t: t.strftime("%Y-%m-%dT%H-%M-%SZ")),
    st.sampled_from(
        [
            "",
            "nan",
            "NA",
            "null",
            "now",
            "today",
            "1e400",
            "-1e400",
            "0x10",
            "1_000",
            '"',
            "99999-01-01",
            "\x00",
        ]
    ),
)
names = st.sampled_from(
    ["time", "timestamp", "ghi", "GHI", "global", "dni", "az_deg", "el_deg", "sigma_deg", "x", "", "time "]
)


@st.composite
def csv_texts(draw) -> str:
    header = draw(st.lists(names, min_size=1, max_size=5))
    width = len(header)
    rows = draw(
        st.lists(st.lists(cells, min_size=max(0, width - 1), max_size=width + 2), min_size=0, max_size=6)
    )
    sep = draw(st.sampled_from([",", ", ", ";"]))
    return "\n".join(sep.join(r) for r in [header, *rows]) + draw(st.sampled_from(["", "\n", "\r\n"]))


def _file(data: bytes, suffix: str) -> Path:
    path = _DIR / f"fuzz{suffix}"
    path.write_bytes(data)
    return path


def check_irradiance(data: bytes) -> None:
    path = _file(data, ".csv")
    try:
        rec = read_records([path])
    except InputError as exc:
        assert str(path) in str(exc)
        return
    assert len(rec.times) == len(rec.ghi) > 0
    assert np.all(np.isfinite(rec.times))
    assert np.all((rec.times >= TIME_RANGE[0]) & (rec.times <= TIME_RANGE[1]))
    for values in (rec.ghi, rec.dni):
        if values is not None:
            ok = np.isnan(values) | ((values >= MIN_IRRADIANCE) & (values <= MAX_IRRADIANCE))
            assert np.all(ok) and len(values) == len(rec.times)


def check_observations(data: bytes) -> None:
    path = _file(data, ".csv")
    try:
        obs = read_observations(path)
    except InputError as exc:
        assert str(path) in str(exc)
        return
    assert obs and [o.time for o in obs] == sorted(o.time for o in obs)
    for o in obs:
        assert math.isfinite(o.time) and 0 <= o.az_deg < 360 and -90 <= o.el_deg <= 90
        assert 0 < o.sigma_deg <= 90


@bounded(120)
@given(st.binary(max_size=200))
@example(b"time,ghi\n\xff\xfe,1\n")
@example(b"time,ghi\n1000000000,1,5,6\n")
def test_irradiance_from_any_bytes(data):
    check_irradiance(data)


@bounded(200)
@given(csv_texts())
@example("time,ghi\nnow,100\n")
@example("time,ghi\n1000000000,100,5\n1000000060,200\n")
def test_irradiance_from_any_csv_text(text):
    check_irradiance(text.encode())


@bounded(120)
@given(st.binary(max_size=200))
def test_observations_from_any_bytes(data):
    check_observations(data)


@bounded(200)
@given(csv_texts())
def test_observations_from_any_csv_text(text):
    check_observations(text.encode())


json_values = st.recursive(
    st.one_of(
        st.none(),
        st.booleans(),
        st.integers(),
        st.floats(allow_nan=False, allow_infinity=False),
        st.text(max_size=10),
        st.sampled_from(["2024-03-20T10:15:00Z", "2024-03-20T10:15:00", "enu", "model", "1e400"]),
    ),
    lambda inner: st.one_of(
        st.lists(inner, max_size=3), st.dictionaries(st.text(max_size=5), inner, max_size=3)
    ),
    max_leaves=6,
)
observation_lines = st.fixed_dictionaries(
    {},
    optional={
        "found": st.one_of(st.booleans(), json_values),
        "time": json_values,
        "az_deg": st.one_of(st.floats(-1000, 1000), json_values),
        "el_deg": st.one_of(st.floats(-100, 100), json_values),
        "sigma_deg": st.one_of(st.floats(0, 100), json_values),
        "frame": json_values,
    },
)


@bounded(150)
@given(st.lists(st.one_of(observation_lines, json_values), min_size=1, max_size=5))
@example([{"found": True, "time": "2024-03-20T10:15:00Z", "az_deg": 1e308 * 10, "el_deg": 10}])
def test_observations_from_any_json_lines(lines):
    text = "\n".join(json.dumps(x) for x in lines)
    check_observations(("{}\n" if not text.lstrip().startswith("{") else "").encode() + text.encode())


# -- what a reader accepts is what the file says ---------------------------------------------
sample_times = st.floats(min_value=0.0, max_value=4.0e9).map(lambda t: round(t))
irradiances = st.one_of(
    st.floats(MIN_IRRADIANCE, MAX_IRRADIANCE).map(lambda x: round(x, 3)), st.just(math.nan)
)


@bounded(100)
@given(
    st.lists(st.tuples(sample_times, irradiances, irradiances), min_size=1, max_size=8),
    st.sampled_from(["posix", "iso"]),
    st.permutations(["time", "ghi", "dni", "note"]),
)
def test_an_irradiance_file_reads_back_as_written(rows, time_form, columns):
    """Written in any column order and either time form, a plausible record is read exactly."""
    from datetime import UTC, datetime

    def cell(col, t, g, d):
        if col == "time":
            return str(t) if time_form == "posix" else datetime.fromtimestamp(t, UTC).isoformat()
        if col == "note":
            return "x"
        v = g if col == "ghi" else d
        return "" if math.isnan(v) else repr(v)

    if all(math.isnan(g) for _, g, _ in rows):
        rows = [(rows[0][0], 1.0, rows[0][2]), *rows[1:]]
    text = ",".join(columns) + "\n" + "".join(",".join(cell(c, *r) for c in columns) + "\n" for r in rows)
    rec = read_records([_file(text.encode(), ".csv")])
    np.testing.assert_array_equal(rec.times, [t for t, _, _ in rows])
    np.testing.assert_array_equal(rec.ghi, [g for _, g, _ in rows])
    np.testing.assert_array_equal(rec.dni, [d for _, _, d in rows])


@bounded(60)
@given(st.lists(sample_times, min_size=1, max_size=5), st.integers(0, 4), st.integers(1, 3))
def test_a_row_longer_than_the_header_is_refused_not_shifted(times, at, extra):
    """A first row with one field too many made pandas take its first field as an index and
    shift every column (time <- GHI): refused, whichever row it is."""
    rows = [f"{t},{100 + i}" for i, t in enumerate(times)]
    at = min(at, len(rows) - 1)
    rows[at] += ",7" * extra
    path = _file(("time,ghi\n" + "\n".join(rows) + "\n").encode(), ".csv")
    try:
        read_records([path])
    except InputError as exc:
        assert f"row {at + 2}" in str(exc) or f"line {at + 2}" in str(exc)
    else:
        raise AssertionError("a row longer than the header was read")


@bounded(60)
@given(st.floats(0, 359.9), st.floats(-89.9, 89.9), st.integers(1, 3))
def test_an_observation_row_longer_than_the_header_is_refused(az, el, extra):
    """A decimal comma ("10,5") silently shifted the next columns: refused, naming the row."""
    line = f"2024-03-20T10:15:00Z,{az:.1f},{el:.1f}" + ",5" * extra
    path = _file(f"time,az_deg,el_deg\n{line}\n".encode(), ".csv")
    try:
        read_observations(path)
    except InputError as exc:
        assert "row 2" in str(exc)
    else:
        raise AssertionError("a row longer than the header was read")
