"""The loop keeps its history and the learned state in the SQLite store."""

import json

from controller.history import History
from controller.store import Store
from controller.sunpath.policy import SunPathSource
from controller.sunpath.state import STORE_KEY
from heliotrack.scenario import load_scenario
from tests.conftest import REPO


class TruthSensor:
    """A camera that sees the sun where pvlib's SPA puts it (the loop's sensor seam)."""

    def __init__(self, site):
        self.site = site

    def observe(self, t):
        from controller.sun.source import solar_position
        from controller.sun.types import SunObservation

        sp = solar_position(self.site, [t]).iloc[0]
        return SunObservation(t, float(sp["azimuth"]), float(sp["apparent_elevation"]), 0.05, sensor="truth")

    def observations(self, t):
        return [self.observe(t)]


def test_the_loop_keeps_setpoints_observations_and_the_learned_state(default_plant, tmp_path):
    run, ctl, fws, clock, cfg = default_plant
    store = Store(tmp_path / "state.sqlite")
    ctl.sun = SunPathSource(cfg.site)
    ctl.sensor = TruthSensor(cfg.site)
    ctl.history = History(store, 30)
    ctl.sun.use_store(store, clock.now())
    for _ in range(5):
        run(ctl.cycle())
        clock.sleep(cfg.control.period_s)
    run(ctl.close())
    setpoints, observations = store.history("setpoints"), store.history("observations")
    saved = store.get_state(STORE_KEY)
    store.close()
    assert len(setpoints) == 2 * 5 and {r[1] for r in setpoints} == {"dual-1", "row-1"}
    assert json.loads(setpoints[-1][4]) and [o[1] for o in observations] == ["truth"] * 5
    assert saved is not None and saved.body["format"] == "heliotrack.sunpath.state"
    assert saved.body["filter"]["n_accepted"] + len(saved.body["filter"]["buffer"]) == 5


def test_a_bad_stored_state_is_kept_aside_and_the_filter_starts_afresh(tmp_path):
    site = load_scenario(REPO / "config" / "hil-default.toml").site
    with Store(tmp_path / "s.sqlite") as st:
        st.put_state(
            STORE_KEY,
            {
                "format": "heliotrack.sunpath.state",
                "version": 1,
                "filter": {"kind": "sunpath-kalman", "x": [95.0]},
            },
        )
        src = SunPathSource(site)
        src.use_store(st, now=1.7e9)
        assert src.state_note and "kept it as" in src.state_note
        names = [row[0] for row in st._db.execute("SELECT name FROM state")]  # noqa: SLF001
        assert any(n.startswith("sunpath.invalid-") for n in names)
        assert src.estimate(1.7e9 + 3600).source.value == "ephemeris"
