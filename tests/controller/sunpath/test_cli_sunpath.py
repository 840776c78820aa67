import csv
import io
import json
from pathlib import Path

import pandas as pd
import pytest

from controller.errors import InputError
from controller.sunpath.io import read_observations
from heliotrack.cli import main

from ._synth import ANDIMESHK, SANTIAGO, observations, sample_times


def _write_csv(p, obs):
    with p.open("w") as f:
        f.write("time,az_deg,el_deg,sigma_deg\n")
        for o in obs:
            ts = pd.Timestamp(o.time, unit="s", tz="UTC").tz_convert("Asia/Tehran").isoformat()
            f.write(f"{ts},{o.az_deg:.4f},{o.el_deg:.4f},0.3\n")
    return p


@pytest.fixture(scope="module")
def obs_csv(tmp_path_factory):
    obs, _, _ = observations(ANDIMESHK, sample_times("2024-03-10", 3, 3.5), seed=21)
    return _write_csv(tmp_path_factory.mktemp("cli") / "obs.csv", obs)


@pytest.fixture(scope="module")
def paper_csv(tmp_path_factory):
    """The paper's February sampling (08:00-16:30), uneven about a 12:31 noon."""
    t = sample_times("2024-02-12", 2, 3.5, start_h=8.0, n_per_day=35)
    obs, _, _ = observations(ANDIMESHK, t, seed=22)
    return _write_csv(tmp_path_factory.mktemp("cli") / "paper.csv", obs)


def test_kalman_rows_and_state(obs_csv, tmp_path, capsys):
    state = tmp_path / "state.json"
    assert main(["sunpath", str(obs_csv), "--state", str(state)]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert [r["date"] for r in rows] == ["2024-03-10", "2024-03-11", "2024-03-12"]
    for key in ("noon_utc", "noon_el_deg", "declination_deg", "lat_deg", "lon_deg", "n_obs"):
        assert rows[-1][key] != ""
    assert rows[-1]["method"] == "kalman"
    assert abs(float(rows[-1]["lat_deg"]) - ANDIMESHK.latitude) < 0.3
    assert json.loads(state.read_text())["format"] == "heliotrack.sunpath.state"
    assert main(["sunpath", "predict", "--state", str(state), "--at", "2024-03-13T12:00:00+03:30"]) == 0
    pred = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert len(pred) == 1 and pred[0]["source"] == "predicted"
    assert 150 < float(pred[0]["az_deg"]) < 210


def test_seed_jsonl(obs_csv, tmp_path):
    out = tmp_path / "o.jsonl"
    assert (
        main(
            [
                "sunpath",
                str(obs_csv),
                "--method",
                "seed",
                "--lat",
                "32.4835",
                "--lon",
                "48.3364",
                "--utc-offset",
                "3.5",
                "--out",
                str(out),
            ]
        )
        == 0
    )
    rows = [json.loads(line) for line in out.read_text().splitlines()]
    assert len(rows) == 3 and rows[0]["method"] == "seed"
    assert rows[0]["declination_deg"] is not None


def test_predict_from_ephemeris_and_errors(tmp_path, capsys):
    assert (
        main(
            [
                "sunpath",
                "predict",
                "--lat",
                "32.4835",
                "--lon",
                "48.3364",
                "--start",
                "2024-03-13T08:00:00Z",
                "--end",
                "2024-03-13T09:00:00Z",
                "--step-min",
                "30",
            ]
        )
        == 0
    )
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert [r["source"] for r in rows] == ["ephemeris"] * 3
    bad = tmp_path / "bad.csv"
    bad.write_text("time,az_deg,el_deg\n2024-03-01T08:00:00Z,100,x\n")
    assert main(["sunpath", str(bad)]) == 2
    assert "row 2, column 'el_deg'" in capsys.readouterr().err
    assert main(["sunpath", "predict", "--at", "2024-03-01T08:00:00Z"]) == 2
    assert main(["sunpath", str(bad), "--lat", "10"]) == 2


def test_cli_default_declination_mode_is_the_filter_default():
    import argparse

    from controller.sunpath.kalman import KalmanConfig
    from heliotrack.commands import sunpath

    p = argparse.ArgumentParser()
    sub = p.add_subparsers()
    sunpath.register(sub)
    args = p.parse_args(["sunpath", "obs.csv"])
    assert args.declination == KalmanConfig().declination == "ephemeris"
    assert args.noon_elevation == "measured"
    assert args.fit == "mirrored" and not args.chain_prior  # the paper's Table 3


def test_seed_fit_variants_are_selectable(paper_csv, capsys):
    # The same file through --fit mirrored (default), --fit whole-day and --chain-prior:
    # the CLI rows are run_seed's rows for that choice, and the choices differ.
    from controller.sunpath.io import read_observations
    from controller.sunpath.parabola import run_seed

    obs = read_observations(paper_csv)
    t, az, el = [o.time for o in obs], [o.az_deg for o in obs], [o.el_deg for o in obs]
    noons = {}
    for extra, kw in (
        ([], {}),
        (["--fit", "whole-day"], {"fit": "whole-day"}),
        (["--chain-prior"], {"use_prior": True}),
    ):
        assert main(["sunpath", str(paper_csv), "--method", "seed", "--utc-offset", "3.5", *extra]) == 0
        rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
        want, _ = run_seed(t, az, el, 3.5, **kw)
        assert [r["noon_utc"] for r in rows] == [w.as_row()["noon_utc"] for w in want]
        noons[" ".join(extra)] = [w.noon_utc for w in want]
    assert all(abs(a - b) > 1.0 for a, b in zip(noons[""], noons["--fit whole-day"]))
    assert noons[""][0] == noons["--chain-prior"][0]  # day 1 has no yesterday
    assert abs(noons[""][1] - noons["--chain-prior"][1]) > 1.0


def test_sky_only_mode_and_seed_variant(obs_csv, tmp_path, capsys):
    assert main(["sunpath", str(obs_csv), "--declination", "free", "--utc-offset", "3.5"]) == 0
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert len(rows) == 3 and abs(float(rows[-1]["lat_deg"]) - ANDIMESHK.latitude) < 0.3
    assert (
        main(
            [
                "sunpath",
                str(obs_csv),
                "--method",
                "seed",
                "--lat",
                "32.4835",
                "--lon",
                "48.3364",
                "--utc-offset",
                "3.5",
                "--noon-elevation",
                "vertex",
            ]
        )
        == 0
    )
    rows = list(csv.DictReader(io.StringIO(capsys.readouterr().out)))
    assert len(rows) == 3 and rows[0]["method"] == "seed"


def test_a_state_of_another_site_is_refused_for_this_one(tmp_path, capsys):
    """An audit's case: --lat/--lon were ignored once a state was loaded (el -10 for 34 deg)."""
    obs = Path(__file__).resolve().parents[3] / "samples" / "observations.csv"
    st = tmp_path / "st.json"
    assert main(["sunpath", str(obs), "--state", str(st), "--out", str(tmp_path / "days.csv")]) == 0
    argv = ["sunpath", "predict", "--state", str(st), "--lat", "-33.45", "--lon", "-70.67"]
    assert main([*argv, "--at", "2024-06-01T16:40Z"]) == 2
    assert "learned at lat 32.4" in capsys.readouterr().err


def test_sunpath_out_and_state_mistakes_lose_nothing(tmp_path, capsys):
    """An audit's cases: --out a folder was a traceback after the state was saved; no row
    truncated an existing file; predict with a missing state created it."""
    one = tmp_path / "one.csv"
    one.write_text("time,az_deg,el_deg\n2024-03-20T09:00:00Z,120,30\n")
    keep = tmp_path / "keep.csv"
    keep.write_text("precious")
    assert main(["sunpath", str(one), "--method", "seed", "--out", str(keep)]) == 0
    assert keep.read_text() == "precious" and "no row to write" in capsys.readouterr().err
    assert main(["sunpath", str(one), "--out", str(tmp_path)]) == 2
    assert "is a folder" in capsys.readouterr().err
    missing = tmp_path / "nonexist.json"
    assert main(["sunpath", "predict", "--state", str(missing), "--at", "2024-03-20T09:00Z"]) == 2
    assert not missing.exists()


def test_found_must_be_a_boolean(tmp_path):
    p = tmp_path / "obs.jsonl"
    p.write_text('{"found": "false", "time": "2024-03-01T09:00:00Z", "az_deg": 120, "el_deg": 30}\n')
    with pytest.raises(InputError, match=r"key 'found': expected true or false, got 'false'"):
        read_observations(p)


def test_a_file_fed_again_into_its_state_is_not_counted_twice(tmp_path, capsys):
    """An audit's case: five runs of one file into one --state took lat sigma from 0.0158
    to 0.0073 deg, 680 observations accepted for 136."""
    obs = Path(__file__).resolve().parents[3] / "samples" / "observations.csv"
    st = tmp_path / "st.json"
    assert main(["sunpath", str(obs), "--state", str(st), "--out", str(tmp_path / "a.csv")]) == 0
    first = json.loads(st.read_text())
    capsys.readouterr()
    assert main(["sunpath", str(obs), "--state", str(st), "--out", str(tmp_path / "b.csv")]) == 0
    assert "skipped: the state has them already" in capsys.readouterr().err
    again = json.loads(st.read_text())
    assert again["filter"]["P"] == first["filter"]["P"]


def test_the_seed_method_says_why_no_day_was_fitted(tmp_path, capsys):
    """It had said only "no row to write (no day could be fitted)"."""
    obs = tmp_path / "mornings.csv"
    obs.write_text(
        "time,az_deg,el_deg\n"
        "2024-03-20T07:00:00Z,100,10\n2024-03-20T08:00:00Z,110,20\n2024-03-20T09:00:00Z,120,30\n"
        "2024-03-21T08:00:00Z,110,20\n2024-03-21T09:00:00Z,120,30\n"
    )
    assert main(["sunpath", str(obs), "--method", "seed", "--utc-offset", "0"]) == 0
    err = capsys.readouterr().err
    assert "no day could be fitted: 2024-03-20: the elevation only rises (a morning: no noon in it)" in err, (
        err
    )
    assert "2024-03-21: 2 sample(s), 3 at least" in err, err


def test_an_offset_that_splits_the_noons_is_warned_about(tmp_path, capsys):
    """An audit's case: --utc-offset 12 at a site on UTC cut every day at its noon, and the
    fit went on without a word."""
    rows = ["time,az_deg,el_deg"]
    for day in (20, 21):
        for h, el in ((9, 30), (10, 38), (11, 42), (12, 43), (13, 41), (14, 36), (15, 28)):
            rows.append(f"2024-03-{day}T{h:02d}:00:00Z,{90 + 15 * (h - 6)},{el}")
    obs = tmp_path / "obs.csv"
    obs.write_text("\n".join(rows) + "\n")
    assert main(["sunpath", str(obs), "--method", "seed", "--utc-offset", "12"]) == 0
    err = capsys.readouterr().err
    assert "--utc-offset 12: the days' highest sun falls at 00:00 local (median)" in err, err
    assert main(["sunpath", str(obs), "--method", "seed", "--utc-offset", "0"]) == 0
    assert "--utc-offset" not in capsys.readouterr().err


@pytest.fixture(scope="module")
def southern_csv(tmp_path_factory):
    """Two days at Santiago (33.45 S, 70.67 W)."""
    obs, _, _ = observations(SANTIAGO, sample_times("2024-04-10", 2, -4.0), seed=23)
    return _write_csv(tmp_path_factory.mktemp("cli") / "south.csv", obs)


@pytest.mark.parametrize(
    ("lat", "lon", "cause"),
    [
        ("33.4489", "-70.6693", "likely the latitude's sign (the sky's is -33."),
        ("-33.4489", "70.6693", "likely the longitude's sign (the sky's is -70."),
    ],
)
def test_a_sky_that_does_not_fit_the_site_is_refused(southern_csv, tmp_path, capsys, lat, lon, cause):
    """An audit's case: Cape Town data with --lat 33.9 exited 0, every observation
    rejected, and wrote the given site's ephemeris (noon elevation 79.5 where the sky
    says 32.7), without a word."""
    out, state = tmp_path / "days.csv", tmp_path / "st.json"
    out.write_text("precious")
    argv = ["sunpath", str(southern_csv), "--lat", lat, "--lon", lon]
    assert main([*argv, "--out", str(out), "--state", str(state)]) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the sky does not fit --lat" in err and cause in err, err
    assert "observations rejected" in err and "nothing written" in err, err
    assert out.read_text() == "precious" and not state.exists()
    assert main(["sunpath", "predict", str(southern_csv), *argv[2:], "--at", "2024-04-12T12:00Z"]) == 2


@pytest.mark.parametrize(
    ("lat", "lon", "shift_h", "cause"),
    [
        ("33.4489", "-70.6693", 0, "likely the latitude's sign (the sky's is -33."),
        ("-33.4489", "70.6693", 0, "likely the longitude's sign (the sky's is -70."),
        ("-33.4489", "-70.6693", -4, "likely the time stamps' zone (they read -4 h from UTC"),
    ],
)
def test_the_seed_method_refuses_a_sky_that_does_not_fit_the_site(
    southern_csv, tmp_path, capsys, lat, lon, shift_h, cause
):
    """The seed method had used --lat only for its declination: with the latitude's sign
    wrong it printed a declination of 75 deg and exited 0."""
    src = southern_csv
    if shift_h:  # Santiago's local times (UTC-4) written as if UTC
        rows = southern_csv.read_text().splitlines()
        src = tmp_path / "local.csv"
        src.write_text("\n".join([rows[0], *(_shifted(r, shift_h) for r in rows[1:])]) + "\n")
    out = tmp_path / "days.csv"
    out.write_text("precious")
    argv = ["sunpath", str(src), "--method", "seed", "--lat", lat, "--lon", lon, "--out", str(out)]
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert err.count("\n") == 1 and "the sky does not fit --lat" in err and cause in err, err
    assert out.read_text() == "precious"
    assert (
        main(["sunpath", str(southern_csv), "--method", "seed", "--lat", "-33.4489", "--lon", "-70.6693"])
        == 0
    )
    assert capsys.readouterr().err == ""


def _shifted(row: str, hours: float) -> str:
    from datetime import datetime, timedelta

    t, rest = row.split(",", 1)
    when = datetime.fromisoformat(t.replace("Z", "+00:00")) + timedelta(hours=hours)
    return f"{when.isoformat()},{rest}"


def test_a_sky_that_fits_the_site_gives_no_alarm_despite_distractors(southern_csv, tmp_path, capsys):
    """Rejecting some observations (reflections, clouds' edges) is normal: no error, no
    warning, the site kept."""
    rows = southern_csv.read_text().splitlines()
    for i in range(3, len(rows), 4):  # every 4th observation a random point of the sky
        t = rows[i].split(",")[0]
        rows[i] = f"{t},{(97 * i) % 360},{(13 * i) % 60},0.3"
    noisy = tmp_path / "noisy.csv"
    noisy.write_text("\n".join(rows) + "\n")
    assert main(["sunpath", str(noisy), "--lat", "-33.4489", "--lon", "-70.6693"]) == 0
    cap = capsys.readouterr()
    got = list(csv.DictReader(io.StringIO(cap.out)))
    assert cap.err == "" and sum(int(r["n_rejected"]) for r in got) > 0


def test_most_observations_rejected_without_a_measured_offset_is_warned_about(southern_csv, tmp_path, capsys):
    """Two hours of sky (too few to measure the offset) with the latitude's sign wrong."""
    short = tmp_path / "short.csv"
    short.write_text("\n".join(southern_csv.read_text().splitlines()[:9]) + "\n")
    assert main(["sunpath", str(short), "--lat", "33.4489", "--lon", "-70.6693"]) == 0
    err = capsys.readouterr().err
    assert "7 of 8 observations rejected: the sky may not fit --lat/--lon" in err, err
    assert main(["sunpath", str(short), "--lat", "-33.4489", "--lon", "-70.6693"]) == 0
    assert capsys.readouterr().err == ""
