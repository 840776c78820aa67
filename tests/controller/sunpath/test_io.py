import pytest

from controller.errors import InputError
from controller.sunpath.io import read_observations


def _write(tmp_path, text):
    p = tmp_path / "obs.csv"
    p.write_text(text)
    return p


def test_reads_sorted_with_default_sigma(tmp_path):
    p = _write(
        tmp_path,
        "time,az_deg,el_deg,sigma_deg\n"
        "2024-03-01T09:00:00Z,170,50,\n"
        "2024-03-01T08:15:00+03:30,-10,20.5,0.5\n\n",
    )
    obs = read_observations(p)
    assert [o.el_deg for o in obs] == [20.5, 50.0]
    assert obs[0].time == pytest.approx(1709268300.0)
    assert obs[0].az_deg == 350.0 and obs[0].sigma_deg == 0.5 and obs[1].sigma_deg == 0.3


@pytest.mark.parametrize(
    "text,needle",
    [
        ("time,az_deg\n2024-03-01T09:00:00Z,1\n", "missing column(s) el_deg"),
        (
            "time,az_deg,el_deg\n2024-03-01T09:00:00Z,1,2\n2024-03-01T09:15:00Z,1,abc\n",
            "row 3, column 'el_deg'",
        ),
        ("time,az_deg,el_deg\n2024-03-01T09:00:00Z,1,95\n", "between -90 and 90"),
        ("time,az_deg,el_deg\n2024-03-01 09:00,1,2\n", "no zone"),
        ("time,az_deg,el_deg\nyesterday,1,2\n", "row 2, column 'time'"),
        ("time,az_deg,el_deg,sigma_deg\n2024-03-01T09:00:00Z,1,2,-1\n", "column 'sigma_deg'"),
        ("time,az_deg,el_deg\n", "no observations"),
        # an audit's case: a night row (or a zenith angle's sign) had been taken as a sighting
        (
            "time,az_deg,el_deg\n2024-03-01T02:00:00Z,10,-25\n",
            "row 2, column 'el_deg': -25 deg, a sun seen below",
        ),
    ],
)
def test_clear_errors(tmp_path, text, needle):
    with pytest.raises(InputError) as err:
        read_observations(_write(tmp_path, text))
    assert needle in str(err.value) and "obs.csv" in str(err.value)


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="cannot read"):
        read_observations(tmp_path / "nope.csv")


def test_a_sun_seen_just_under_the_horizon_is_taken(tmp_path):
    """Refraction and a high site's dip show the sun a little under 0 deg."""
    obs = read_observations(_write(tmp_path, "time,az_deg,el_deg\n2024-03-01T06:00:00Z,90,-0.8\n"))
    assert obs[0].el_deg == pytest.approx(-0.8)


def test_a_night_line_of_estimate_json_is_refused(tmp_path):
    p = tmp_path / "obs.jsonl"
    p.write_text('{"found": true, "time": "2024-03-01T02:00:00Z", "az_deg": 10, "el_deg": -25}\n')
    with pytest.raises(InputError, match="line 1, key 'el_deg': -25 deg, a sun seen below the horizon"):
        read_observations(p)
