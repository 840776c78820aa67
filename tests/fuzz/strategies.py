"""What the fuzzers share: bounded hypothesis settings, a scratch folder, TOML values and a
TOML writer.

Every fuzz test runs a fixed, small number of examples without a per-example deadline (the
machine may be busy), so the whole set stays well under a minute.
"""

from __future__ import annotations

import atexit
import datetime as dt
import math
import os
import shutil
import tempfile
from pathlib import Path
from typing import Any

from hypothesis import HealthCheck, settings
from hypothesis import strategies as st

from controller.calibration.toml_write import toml_string

#: ``HELIOTRACK_FUZZ_SCALE=20 pytest tests/fuzz`` searches 20 times longer (not in CI).
SCALE = float(os.environ.get("HELIOTRACK_FUZZ_SCALE", "1"))


def scratch_dir(prefix: str) -> Path:
    """A fresh temporary folder for a fuzzer's files, removed when the test run ends (the
    ``@given`` tests cannot take pytest's function-scoped ``tmp_path``)."""
    path = Path(tempfile.mkdtemp(prefix=prefix))
    atexit.register(shutil.rmtree, path, ignore_errors=True)
    return path


def bounded(n: int) -> settings:
    """``n`` examples, no deadline, no 'too slow' health check, no example database."""
    return settings(
        max_examples=max(1, round(n * SCALE)),
        deadline=None,
        database=None,
        suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large, HealthCheck.filter_too_much],
    )


# -- TOML ---------------------------------------------------------------------------------
#: Numbers a hostile or careless file may hold: huge integers, floats of every kind.
numbers = st.one_of(
    st.integers(),
    st.integers(min_value=-(2**70), max_value=2**70),
    st.sampled_from([0, -1, 1, 2**31, 2**63 - 1, -(2**63), 10**400, -(10**400)]),
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([0.0, -0.0, 1e-320, 1e308, -1e308, 90.0, 360.0, 65.535, 65.536]),
)
texts = st.one_of(
    st.text(max_size=20),
    st.sampled_from(
        [
            "",
            "hil",
            "~nosuchuser_heliotrack/x",
            "a\x00b",
            "x" * 5000,
            "../../etc",
            "device:9",
            "\n",
            "0.0.0.0",
        ]
    ),
)
dates = st.one_of(
    st.dates(),
    st.datetimes(timezones=st.sampled_from([None, dt.UTC, dt.timezone(dt.timedelta(hours=-5))])),
    st.times(),
)
scalars = st.one_of(st.booleans(), numbers, texts, dates)
keys = st.one_of(
    st.text(max_size=12),
    st.sampled_from(["site", "trackers", "links", "kind", "type", "stow", "name", "link", "device_id"]),
)
toml_values = st.recursive(
    scalars,
    lambda inner: st.one_of(
        st.lists(inner, max_size=4),
        st.dictionaries(keys, inner, max_size=4),
    ),
    max_leaves=12,
)
documents = st.dictionaries(keys, toml_values, max_size=6)


def dumps_value(v: Any) -> str:
    """One TOML value, inline (tables as inline tables)."""
    if isinstance(v, bool):
        return "true" if v else "false"
    if isinstance(v, int):
        return str(v)
    if isinstance(v, float):
        if math.isnan(v):
            return "nan"
        if math.isinf(v):
            return "inf" if v > 0 else "-inf"
        return repr(v)
    if isinstance(v, str):
        return toml_string(v)
    if isinstance(v, (dt.datetime, dt.date, dt.time)):
        return v.isoformat()
    if isinstance(v, (list, tuple)):
        return "[" + ", ".join(dumps_value(x) for x in v) + "]"
    if isinstance(v, dict):
        return "{" + ", ".join(f"{toml_string(str(k))} = {dumps_value(x)}" for k, x in v.items()) + "}"
    raise TypeError(type(v))


def dumps(doc: dict[str, Any]) -> str:
    """A TOML document: one ``key = value`` line per top-level key."""
    return "".join(f"{toml_string(str(k))} = {dumps_value(v)}\n" for k, v in doc.items())


# -- mutations of a valid document ----------------------------------------------------------
def paths(doc: Any, prefix: tuple = ()) -> list[tuple]:
    """Every key path inside ``doc`` (dict keys and list indices)."""
    out = []
    if isinstance(doc, dict):
        for k, v in doc.items():
            out.append((*prefix, k))
            out += paths(v, (*prefix, k))
    elif isinstance(doc, list):
        for i, v in enumerate(doc):
            out.append((*prefix, i))
            out += paths(v, (*prefix, i))
    return out


def _parent(doc: Any, path: tuple) -> Any:
    for p in path[:-1]:
        doc = doc[p]
    return doc


@st.composite
def mutated(draw, base: dict[str, Any], rounds: int = 3) -> dict[str, Any]:
    """``base`` with up to ``rounds`` values replaced, deleted or added at random places."""
    import copy

    doc = copy.deepcopy(base)
    for _ in range(draw(st.integers(1, rounds))):
        where = paths(doc)
        if not where:
            break
        path = draw(st.sampled_from(where))
        parent = _parent(doc, path)
        action = draw(st.sampled_from(["same kind", "same kind", "nudge", "replace", "delete", "add"]))
        old = parent[path[-1]]
        if action == "same kind" and isinstance(old, (bool, int, float, str)):
            kind = st.booleans() if isinstance(old, bool) else texts if isinstance(old, str) else numbers
            parent[path[-1]] = draw(kind)
        elif action == "delete":
            del parent[path[-1]]
        elif action == "add" and isinstance(parent, dict):
            parent[draw(keys)] = draw(toml_values)
        elif action == "nudge" and isinstance(old, (int, float)) and abs(old) < 1e15:
            parent[path[-1]] = draw(
                st.sampled_from([-old, old + 1, old - 1, old * 10, old + 1e-9, 0, old + 360.0, old - 360.0])
            )
        else:
            parent[path[-1]] = draw(toml_values)
    return doc
