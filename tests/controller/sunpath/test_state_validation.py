"""A learned state is checked on load: a state that is not physical or not plausible is
refused with one line naming the file and the field, and the controller starts safely
without ever overwriting or deleting the file (issue 13, item 8)."""

import json
import logging
import time

import numpy as np
import pandas as pd
import pytest

from controller.sun.types import EstimateSource
from controller.sunpath.kalman import KalmanConfig, SunPathKalman
from controller.sunpath.policy import SunPathSource
from controller.sunpath.state import StateError, load_state, save_state

from ._synth import ANDIMESHK, observations, sample_times

NOW = pd.Timestamp("2024-03-02T12:00:00Z").timestamp()


@pytest.fixture(scope="module", params=["ephemeris", "free"])
def good_doc(request, tmp_path_factory):
    """A saved state after a day of learning without a site (a buffer is added by hand)."""
    obs, _, _ = observations(ANDIMESHK, sample_times("2024-03-01", 1, 3.5), seed=3)
    kf = SunPathKalman(KalmanConfig(declination=request.param))
    for o in obs:
        kf.update(o)
    assert kf.initialised
    path = tmp_path_factory.mktemp("good") / "state.json"
    save_state(path, kf)
    doc = json.loads(path.read_text())
    doc["filter"]["buffer"] = [[kf.t - 600.0, 200.0, 40.0, 0.3]]
    return doc


def _set(doc, key, value):
    doc = json.loads(json.dumps(doc))
    f = doc["filter"]
    if key.startswith("x."):
        f["x"][int(key[2:])] = value
    elif key.startswith("P."):
        i, j = map(int, key[2:].split(","))
        f["P"][i][j] = value
    elif key.startswith("buffer."):
        f["buffer"][0][int(key[7:])] = value
    else:
        f[key] = value
    return doc


Y2100 = pd.Timestamp("2100-01-01T12:00:00Z").timestamp()
BAD = [
    ("x.0", 95.0, "lat_deg"),  # latitude past the pole
    ("x.0", -117.0, "lat_deg"),
    ("x.5", -24.0, "refraction_scale"),  # a negative atmosphere
    ("P.0,0", 1e12, "P[lat_deg]"),  # absurd variance
    ("P.0,1", 0.5, "P"),  # not symmetric
    ("P.2,2", -1.0, "P["),  # negative variance
    ("t", Y2100, "'filter.t'"),  # in the future
    ("t", 100.0, "'filter.t'"),  # before 2000
    ("n_accepted", -3, "n_accepted"),
    ("n_rejected", -1, "n_rejected"),
    ("mode", "magic", "mode"),
    ("buffer.1", float("nan"), "buffer"),  # NaN azimuth (json writes NaN)
    ("buffer.2", 120.0, "buffer"),  # elevation past the zenith
    ("buffer.3", -0.3, "buffer"),  # negative sigma
    ("buffer.0", Y2100, "buffer"),  # an observation from 2100
]


@pytest.mark.parametrize("key, value, field", BAD, ids=[f"{k}={v}" for k, v, _ in BAD])
def test_unphysical_or_implausible_state_is_refused(tmp_path, good_doc, key, value, field):
    path = tmp_path / "state.json"
    path.write_text(json.dumps(_set(good_doc, key, value)))
    with pytest.raises(StateError) as err:
        # the caller's "now" (the wall clock here) is what judges "in the future"
        load_state(path, now=time.time()) if value == Y2100 else load_state(path)
    msg = str(err.value)
    assert str(path) in msg and field in msg and "\n" not in msg


def test_the_good_state_loads_and_the_future_is_judged_against_the_callers_now(tmp_path, good_doc):
    path = tmp_path / "state.json"
    path.write_text(json.dumps(good_doc))
    kf = load_state(path)
    assert kf is not None and kf.initialised
    t = kf.t
    assert load_state(path, now=t - 3600.0) is not None  # within a day's slack
    with pytest.raises(StateError, match="filter.t"):
        load_state(path, now=t - 3 * 86400.0)  # saved "three days from now"
    # a latitude of 95 is not rescued by the longitude normalisation either
    bad = _set(_set(good_doc, "x.0", 95.0), "x.1", 228.3364)
    path.write_text(json.dumps(bad))
    with pytest.raises(StateError, match="lat_deg"):
        load_state(path)


def _bad_file(tmp_path, good_doc):
    path = tmp_path / "sunpath.json"
    text = json.dumps(_set(good_doc, "x.0", 95.0))
    path.write_text(text)
    return path, text


def test_source_with_an_invalid_state_starts_from_the_ephemeris_and_keeps_the_file(
    tmp_path, good_doc, caplog
):
    path, text = _bad_file(tmp_path, good_doc)
    with caplog.at_level(logging.WARNING):
        src = SunPathSource(site=ANDIMESHK, state_path=path, now=NOW)
    warnings = [r for r in caplog.records if r.levelno >= logging.WARNING]
    assert len(warnings) == 1 and "\n" not in warnings[0].getMessage()
    assert str(path) in warnings[0].getMessage() and "lat_deg" in warnings[0].getMessage()
    assert "fix or remove" not in warnings[0].getMessage()  # it was moved aside already
    assert not src.kf.initialised  # nothing of the bad state
    e = src.estimate(NOW)
    assert e is not None and e.source is EstimateSource.EPHEMERIS
    # the bad file is kept aside, byte for byte, and a fresh state takes its place
    aside = [p for p in tmp_path.iterdir() if p.name.startswith("sunpath.json.invalid-")]
    assert len(aside) == 1 and aside[0].read_text() == text
    src.save()
    assert load_state(path) is not None and aside[0].read_text() == text


def test_source_without_a_site_waits_to_learn(tmp_path, good_doc, caplog):
    path, _ = _bad_file(tmp_path, good_doc)
    with caplog.at_level(logging.WARNING):
        src = SunPathSource(state_path=path, now=NOW)
    assert src.estimate(NOW) is None and not src.kf.initialised
    assert sum(r.levelno >= logging.WARNING for r in caplog.records) == 1


@pytest.mark.parametrize("content", ["{not json", json.dumps({"format": "other"})])
def test_source_with_a_corrupt_file_does_not_crash(tmp_path, content, caplog):
    path = tmp_path / "sunpath.json"
    path.write_text(content)
    with caplog.at_level(logging.WARNING):
        src = SunPathSource(site=ANDIMESHK, state_path=path, now=NOW)
    assert src.estimate(NOW).source is EstimateSource.EPHEMERIS
    assert [r.getMessage().count("\n") for r in caplog.records] == [0]
    kept = [p for p in tmp_path.iterdir() if ".invalid-" in p.name]
    assert len(kept) == 1 and kept[0].read_text() == content


def test_a_good_state_is_neither_refused_nor_reset(tmp_path, good_doc, caplog):
    path = tmp_path / "sunpath.json"
    path.write_text(json.dumps(good_doc))
    with caplog.at_level(logging.WARNING):
        src = SunPathSource(state_path=path, now=NOW)
    assert src.kf.initialised and not caplog.records
    assert [p.name for p in tmp_path.iterdir()] == ["sunpath.json"]
    assert np.allclose(src.kf.x, good_doc["filter"]["x"])


def test_save_refuses_to_replace_a_file_that_reads_but_fails_validation(tmp_path, good_doc):
    path, text = _bad_file(tmp_path, good_doc)
    with pytest.raises(StateError):
        save_state(path, SunPathKalman())
    assert path.read_text() == text


def test_a_state_learned_at_another_site_is_set_aside(tmp_path, good_doc, caplog):
    # Learned at Andimeshk (site unknown to it); the plant's configured site is Santiago:
    # the configuration was changed, and the old learning does not belong to this site.
    from ._synth import SANTIAGO

    path = tmp_path / "sunpath.json"
    path.write_text(json.dumps(good_doc))
    with caplog.at_level(logging.WARNING):
        src = SunPathSource(site=SANTIAGO, state_path=path, now=NOW)
    assert not src.kf.initialised and len(caplog.records) == 1
    assert "configured site" in caplog.records[0].getMessage()
    assert any(p.name.startswith("sunpath.json.invalid-") for p in tmp_path.iterdir())
    # at its own site it is used, and the configured site becomes its prior
    path.write_text(json.dumps(good_doc))
    same = SunPathSource(site=ANDIMESHK, state_path=path, now=NOW)
    assert same.kf.initialised and same.kf.site == ANDIMESHK


def test_a_state_path_that_cannot_be_read_is_left_alone_and_save_does_not_crash(tmp_path, caplog):
    path = tmp_path / "sunpath.json"
    path.mkdir()  # something in the way, not a state file
    (path / "keep.txt").write_text("mine")
    with caplog.at_level(logging.WARNING):
        src = SunPathSource(site=ANDIMESHK, state_path=path, now=NOW)
        src.save()
    assert src.estimate(NOW).source is EstimateSource.EPHEMERIS
    assert len(caplog.records) == 1 and "will not be saved" in caplog.records[0].getMessage()
    assert (path / "keep.txt").read_text() == "mine"


def test_a_missing_state_file_is_one_line_and_a_safe_start(tmp_path, caplog):
    path = tmp_path / "sunpath.json"
    with caplog.at_level(logging.INFO, logger="heliotrack.sunpath"):
        src = SunPathSource(site=ANDIMESHK, state_path=path, now=NOW)
    msgs = [r.getMessage() for r in caplog.records]
    assert len(msgs) == 1 and str(path) in msgs[0] and "\n" not in msgs[0]
    assert caplog.records[0].levelno == logging.INFO  # a first start is not a fault
    assert src.estimate(NOW).source is EstimateSource.EPHEMERIS
    src.save()
    assert load_state(path) is not None


def test_a_state_file_nested_too_deeply_is_a_state_error(tmp_path):
    """An audit's case: it had crashed every start with a RecursionError."""
    p = tmp_path / "sunpath.json"
    p.write_text("[" * 100000 + "]" * 100000)
    with pytest.raises(StateError, match="nested too deeply"):
        load_state(p)
