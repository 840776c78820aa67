import numpy as np
import pandas as pd
import pytest

from controller.errors import InputError
from controller.sky.io import read_csv_record, read_records
from heliotrack.cli import main

from .conftest import SITE


def _write(path, ds, time_name="timestamp", ghi_name="GHI", dni_name="DNI", n=None):
    sl = slice(None, n)
    pd.DataFrame(
        {
            time_name: pd.to_datetime(ds["times"][sl], unit="s", utc=True).strftime("%Y-%m-%dT%H:%M:%SZ"),
            ghi_name: ds["ghi"][sl].round(1),
            dni_name: ds["dni"][sl].round(1),
        }
    ).to_csv(path, index=False)
    return path


def test_cli_end_to_end(tmp_path, dataset_1min, capsys):
    f = _write(tmp_path / "station.csv", dataset_1min)
    out = tmp_path / "out"
    assert (
        main(
            ["classify", str(f), "--lat", str(SITE.latitude), "--lon", str(SITE.longitude), "--out", str(out)]
        )
        == 0
    )
    days = pd.read_csv(out / "days.csv")
    assert list(days.columns[:6]) == ["date", "n_samples", "D", "K_T", "class", "truth"]
    assert len(days) == 40 and set(days["class"]) <= {"I", "II", "III"}
    for name in ("thresholds", "class_frequency", "class_stats", "monthly_D", "agreement"):
        assert (out / f"{name}.csv").exists()
    assert (out / "fig1_example_days.png").stat().st_size > 5000
    assert (out / "fig2_monthly_D.png").stat().st_size > 5000
    assert "## 2016" in (out / "tables.md").read_text()
    freq = pd.read_csv(out / "class_frequency.csv")
    assert freq["percent"].sum() == pytest.approx(100.0, abs=0.05)
    assert "agreement with sunshine truth, default" in capsys.readouterr().out
    # the paper's rule fills `class` on request
    out2 = tmp_path / "seed"
    assert (
        main(
            [
                "classify",
                str(f),
                "--lat",
                "55.79",
                "--lon",
                "12.52",
                "--method",
                "seed",
                "--threshold-rule",
                "tertiles",
                "--out",
                str(out2),
            ]
        )
        == 0
    )
    seed = pd.read_csv(out2 / "days.csv")
    assert (seed["class"] == seed["class_seed"]).all()
    assert pd.read_csv(out2 / "thresholds.csv")["rule"].iloc[0] == "tertiles"


def test_column_guessing_and_explicit_names(tmp_path, dataset_1min):
    f = _write(tmp_path / "a.csv", dataset_1min, "Time_UTC", "Global_Horizontal", "dni", n=100)
    rec = read_csv_record(f)
    assert rec.ghi.size == 100 and rec.dni is not None
    g = _write(tmp_path / "b.csv", dataset_1min, "when", "pyr1", "pyr2", n=100)
    with pytest.raises(InputError, match="which column is time column"):
        read_csv_record(g)
    rec = read_csv_record(g, time_col="when", ghi_col="pyr1", dni_col="pyr2")
    assert rec.dni is not None
    with pytest.raises(InputError, match="no column 'nope'"):
        read_csv_record(g, time_col="when", ghi_col="nope")


@pytest.mark.parametrize(
    "body,match",
    [
        ("time,ghi\n2016-06-01T00:00:00Z,1\nyesterday,2\n", r"row 3, column 'time'.*ISO 8601 time"),
        # an audit's cases: read month first (01/04 as 4 Jan) or dated today, exit 0
        (
            "timestamp,ghi\n13/04/2024 10:00,1\n01/04/2024 10:00,2\n",
            r"row 2, column 'timestamp'.*day first or month first",
        ),
        (
            "date,time,ghi\n2024-03-19,20:46:39,0.0\n",
            r"row 2, column 'time': '20:46:39' is a time without a date",
        ),
        ("time,ghi\n2016-06-01T00:00:00Z,1\n2016-06-01T00:01:00Z,-300\n", r"row 3, column 'ghi'.*between"),
        ("time,ghi\n2016-06-01T00:00:00Z,1\n2016-06-01T00:01:00Z,lots\n", r"row 3, column 'ghi'.*'lots'"),
        ("time,ghi\n", "no data rows"),
        ("", "not a readable CSV"),
    ],
)
def test_bad_csv_input(tmp_path, body, match):
    f = tmp_path / "bad.csv"
    f.write_text(body)
    with pytest.raises(InputError, match=match):
        read_csv_record(f)


def test_all_nan_ghi_and_missing_file(tmp_path):
    f = tmp_path / "nan.csv"
    f.write_text("time,ghi\n2016-06-01T00:00:00Z,\n2016-06-01T00:01:00Z,NaN\n")
    with pytest.raises(InputError, match="every GHI value is missing"):
        read_records([f])
    with pytest.raises(InputError, match="file not found"):
        read_records([tmp_path / "none.csv"])


def test_cli_reports_bad_input_without_traceback(tmp_path, capsys):
    f = tmp_path / "bad.csv"
    f.write_text("time,ghi\n2016-06-01T00:00:00Z,1\n2016-06-01T00:01:00Z,abc\n")
    assert main(["classify", str(f), "--lat", "1", "--lon", "2", "--out", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert "row 3" in err and "Traceback" not in err
    assert main(["classify", str(f), "--format", "bsrn", "--lat", "1", "--lon", "2"]) == 2
    assert "not a readable BSRN file" in capsys.readouterr().err
    g = tmp_path / "nolat.csv"
    g.write_text("time,ghi\n2016-06-01T00:00:00Z,1\n2016-06-01T00:01:00Z,2\n")
    assert main(["classify", str(g), "--out", str(tmp_path / "o")]) == 2
    assert "--lat and --lon are required" in capsys.readouterr().err


def test_cli_on_a_short_record_says_why_nothing_was_classified(tmp_path, capsys):
    g = tmp_path / "short.csv"
    t = pd.date_range("2016-06-01T10:00Z", periods=20, freq="1min")
    pd.DataFrame({"time": t.strftime("%Y-%m-%dT%H:%M:%SZ"), "ghi": np.linspace(300, 400, 20)}).to_csv(
        g, index=False
    )
    assert main(["classify", str(g), "--lat", "55.8", "--lon", "12.5", "--out", str(tmp_path / "o")]) == 2
    assert "no day could be classified" in capsys.readouterr().err


def _write_surfrad(path, ds, days=2):
    """A SURFRAD daily-format file (48 whitespace columns, -9999.9 missing) from 1-min data."""
    from pvlib.iotools.surfrad import SURFRAD_COLUMNS

    t = pd.to_datetime(ds["times"][: days * 1440], unit="s", utc=True)
    rows = []
    for i, ts in enumerate(t):
        vals = dict.fromkeys(SURFRAD_COLUMNS, 0)
        vals.update(
            year=ts.year,
            jday=ts.day_of_year,
            month=ts.month,
            day=ts.day,
            hour=ts.hour,
            minute=ts.minute,
            dt=ts.hour + ts.minute / 60,
            zen=-9999.9,
            dw_solar=round(float(ds["ghi"][i]), 1),
            direct_n=round(float(ds["dni"][i]), 1),
        )
        if i == 700:
            vals["dw_solar"] = -9999.9  # a missing sample
        rows.append(" ".join(str(vals[c]) for c in SURFRAD_COLUMNS))
    path.write_text("Test Station\n   55.790   12.520   20 m version 1\n" + "\n".join(rows) + "\n")
    return path


def test_surfrad_file_through_pvlib_reader(tmp_path, dataset_1min, capsys):
    f = _write_surfrad(tmp_path / "tst16001.dat", dataset_1min)
    out = tmp_path / "out"
    # the site comes from the file's header when --lat/--lon are omitted
    assert main(["classify", str(f), "--format", "surfrad", "--out", str(out)]) == 0
    days = pd.read_csv(out / "days.csv")
    assert "truth" in days and len(days) >= 1
    assert days["n_samples"].max() >= 1430


@pytest.mark.parametrize(
    ("pair", "needle"),
    [(("1.4", "1.2"), "expected D_I <= D_II, got 1.4 1.2"), (("0.5", "1.2"), "expected a number in [1, 2]")],
)
def test_d_thresholds_out_of_order_or_range_are_refused(tmp_path, capsys, pair, needle):
    g = tmp_path / "any.csv"
    g.write_text("time,ghi\n2016-06-01T00:00:00Z,1\n2016-06-01T00:01:00Z,2\n")
    argv = [
        "classify",
        str(g),
        "--lat",
        "1",
        "--lon",
        "2",
        "--d-thresholds",
        *pair,
        "--out",
        str(tmp_path / "o"),
    ]
    try:
        rc = main(argv)
    except SystemExit as exc:  # argparse's own refusal
        rc = exc.code
    assert rc == 2
    err = capsys.readouterr().err
    assert "--d-thresholds" in err and needle in err and "Traceback" not in err
    assert not (tmp_path / "o").exists()


def test_an_out_that_is_a_file_is_refused_before_the_work(tmp_path, capsys):
    g = tmp_path / "any.csv"
    g.write_text("time,ghi\n2016-06-01T00:00:00Z,1\n2016-06-01T00:01:00Z,2\n")
    (tmp_path / "outfile").write_text("keep")
    assert main(["classify", str(g), "--lat", "1", "--lon", "2", "--out", str(tmp_path / "outfile")]) == 2
    err = capsys.readouterr().err
    assert "--out: cannot write to" in err and "Traceback" not in err
    assert (tmp_path / "outfile").read_text() == "keep"


def test_files_of_two_stations_are_refused(tmp_path, monkeypatch):
    """An audit's case: Bondville's and Desert Rock's SURFRAD files were averaged into one
    record at the first file's site; three clear days came out II."""
    import controller.sky.io as sky_io

    def station(path, fmt, ghi_col=None, dni_col=None):
        lat = 40.05 if "bon" in str(path) else 36.624
        t = np.arange(3) * 60.0 + 1.7e9
        return sky_io.Record(t, np.ones(3), None, lat, -100.0, 1000.0, (str(path),))

    monkeypatch.setattr(sky_io, "read_station_record", station)
    with pytest.raises(InputError, match=r"dra24080.dat: latitude 36.624, but bon24080.dat says 40.05"):
        read_records(["bon24080.dat", "dra24080.dat"], "surfrad")
    assert len(read_records(["dra24080.dat", "dra24081.dat"], "surfrad").times) == 6


def test_a_reused_out_keeps_no_table_of_an_earlier_run(tmp_path, dataset_1min):
    """An audit's case: a second run without DNI into the same --out left the first run's
    agreement table there, read as the second's."""
    out = tmp_path / "out"
    site = ["--lat", str(SITE.latitude), "--lon", str(SITE.longitude), "--out", str(out)]
    assert main(["classify", str(_write(tmp_path / "with_dni.csv", dataset_1min)), *site]) == 0
    assert (out / "agreement.csv").exists()
    ghi_only = tmp_path / "ghi_only.csv"
    pd.read_csv(tmp_path / "with_dni.csv").drop(columns="DNI").to_csv(ghi_only, index=False)
    assert main(["classify", str(ghi_only), *site]) == 0
    assert not (out / "agreement.csv").exists()
    assert (out / "days.csv").exists()
