"""Observation files: estimate's JSON lines chain into sunpath; non-UTF-8 names the row."""

import json

import pytest

from controller.errors import InputError
from controller.sunpath.io import read_observations


def test_estimate_json_lines_are_observations(tmp_path):
    lines = [
        {
            "image": "a.png",
            "found": True,
            "time": "2024-03-01T09:00:00Z",
            "frame": "enu",
            "az_deg": 120.5,
            "el_deg": 30.25,
            "sigma_deg": 0.05,
            "quality": [],
        },
        {"image": "b.png", "found": False, "reason": "no_glint", "time": "2024-03-01T09:15:00Z"},
        {
            "image": "c.png",
            "found": True,
            "time": "2024-03-01T08:45:00Z",
            "frame": "model",
            "az_deg": 117.0,
            "el_deg": 27.5,
            "sigma_deg": 0.06,
            "quality": [],
        },
    ]
    p = tmp_path / "obs.jsonl"
    p.write_text("\n".join(json.dumps(d) for d in lines) + "\n")
    obs = read_observations(p)
    assert [(o.az_deg, o.el_deg, o.frame) for o in obs] == [(117.0, 27.5, "model"), (120.5, 30.25, "enu")]
    assert obs[1].sigma_deg == 0.05


@pytest.mark.parametrize(
    "text, needle",
    [
        ('{"found": true, "az_deg": 1, "el_deg": 2}\n', "line 1: found but without a time"),
        ('{"found": true, "time": "2024-03-01T09:00:00Z", "az_deg": 1, "el_deg": 95}\n', "key 'el_deg'"),
        ('{"found": true, "time": "2024-03-01T09:00:00Z"\n', "line 1: not JSON"),
        ('{"found": false}\n', "no observations with found = true (1 without)"),
    ],
)
def test_json_lines_errors_name_the_line(tmp_path, text, needle):
    p = tmp_path / "obs.jsonl"
    p.write_text(text)
    with pytest.raises(InputError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        read_observations(p)


def test_a_non_utf8_file_names_the_row(tmp_path):
    p = tmp_path / "obs.csv"
    p.write_bytes(b"time,az_deg,el_deg\n2024-03-01T09:00:00Z,100,20\n2024-03-01T09:15:00Z,102\xe9,21\n")
    with pytest.raises(InputError, match=r"obs.csv: row 3: not UTF-8 text \(byte 0xe9\)"):
        read_observations(p)


@pytest.mark.parametrize(
    ("rows", "needle"),
    [
        (
            ["2024-03-01T09:00:00Z,120,30", "2024-03-01T09:00:00Z,120,30"],
            "row 3: time 2024-03-01T09:00:00Z repeats row 2 (the same observation twice)",
        ),
        (
            [
                "2024-03-01T09:00:00Z,120,30",
                "2024-03-01T10:00:00Z,130,35",
                "2024-03-01T11:00:00+02:00,121,31",
            ],
            "row 4: time 2024-03-01T09:00:00Z repeats row 2 with another direction",
        ),
    ],
)
def test_a_time_given_twice_is_refused_naming_both_rows(tmp_path, rows, needle):
    p = tmp_path / "obs.csv"
    p.write_text("time,az_deg,el_deg\n" + "\n".join(rows) + "\n")
    with pytest.raises(InputError, match=needle.replace("(", r"\(").replace(")", r"\)")):
        read_observations(p)


def test_a_time_given_twice_in_json_lines_names_the_lines(tmp_path):
    d = {"found": True, "time": "2024-03-01T09:00:00Z", "az_deg": 120.0, "el_deg": 30.0}
    p = tmp_path / "obs.jsonl"
    p.write_text("\n".join(json.dumps(x) for x in (d, {"found": False}, d)) + "\n")
    with pytest.raises(InputError, match="line 3: time 2024-03-01T09:00:00Z repeats line 1"):
        read_observations(p)
