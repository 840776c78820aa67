import json

import pytest

from controller.errors import InputError
from controller.sunpath.kalman import SunPathKalman
from controller.sunpath.state import StateError, load_state, save_state

from ._synth import ANDIMESHK, observations, sample_times


def _kf():
    kf = SunPathKalman(site=ANDIMESHK)
    obs, _, _ = observations(ANDIMESHK, sample_times("2024-03-01", 1, 3.5)[:6], seed=2)
    for o in obs:
        kf.update(o)
    return kf


def test_round_trip_is_atomic(tmp_path):
    path = tmp_path / "sub" / "sunpath.json"
    kf = _kf()
    save_state(path, kf)
    assert [p.name for p in path.parent.iterdir()] == ["sunpath.json"]  # no temp file left
    back = load_state(path)
    assert back.initialised and back.t == kf.t
    assert back.predict(kf.t + 600).el_deg == pytest.approx(kf.predict(kf.t + 600).el_deg)
    assert load_state(tmp_path / "missing.json") is None


@pytest.mark.parametrize(
    "content",
    [
        "{not json",
        json.dumps({"format": "other"}),
        json.dumps({"format": "heliotrack.sunpath.state", "version": 1, "filter": {"kind": "x"}}),
    ],
)
def test_corrupt_file_is_reported_and_kept(tmp_path, content):
    path = tmp_path / "s.json"
    path.write_text(content)
    with pytest.raises(StateError) as err:
        load_state(path)
    assert str(path) in str(err.value) and isinstance(err.value, InputError)
    with pytest.raises(StateError):
        save_state(path, _kf())
    assert path.read_text() == content
    save_state(path, _kf(), overwrite_corrupt=True)
    assert load_state(path).initialised


def test_a_filter_that_never_saw_the_sun_saves_and_loads(tmp_path):
    # An overcast first day: the controller still saves at shutdown.
    from controller.sunpath.kalman import SunPathKalman
    from controller.sunpath.state import load_state, save_state

    kf = SunPathKalman()
    assert not kf.initialised
    path = tmp_path / "state.json"
    save_state(path, kf)
    back = load_state(path)
    assert back is not None and not back.initialised
