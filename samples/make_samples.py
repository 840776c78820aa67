"""Regenerate the sample data the README and docs examples use (deterministic).

    python samples/make_samples.py            # from the repository's top folder

frames/              12 frames of the hotspot camera (config/hil-hotspot.toml), 2024-03-20,
                     every 15 min from 07:00 UTC (local noon is about 08:50 UTC), JPEG q95,
                     with truth.csv: written by ``heliotrack hil record``
observations.csv     three days of sun observations (time, az_deg, el_deg, sigma_deg): pvlib
                     SPA positions every 15 min with 0.05 deg noise, for ``heliotrack sunpath``
irradiance.csv       four days of 1-min GHI and DNI (the HIL sky: clear, partly cloudy,
                     overcast, clear), for ``heliotrack classify``
"""

from __future__ import annotations

import csv
import shutil
import subprocess
import sys
from datetime import UTC, datetime
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
REPO = HERE.parent
LAT, LON, ALT = 32.4835, 48.3364, 150.0


def frames() -> None:
    out = HERE / "frames"
    shutil.rmtree(out, ignore_errors=True)
    cmd = [
        sys.executable,
        "-m",
        "heliotrack.cli",
        "hil",
        "record",
        "--config",
        str(REPO / "config" / "hil-hotspot.toml"),
    ]
    cmd += ["--start", "2024-03-20T07:00:00Z", "--hours", "3", "--every", "900", "--format", "jpg"]
    subprocess.run([*cmd, "--out", str(out), "--no-progress"], check=True)


def observations() -> None:
    from hil.truth import sun_truth

    rng = np.random.default_rng(20240320)
    rows = []
    for day in (20, 21, 22):
        t0 = datetime(2024, 3, day, 3, 0, tzinfo=UTC).timestamp()
        t = t0 + np.arange(0, 12 * 3600, 900)
        sun = sun_truth(t, LAT, LON, ALT)
        for ti, az, el in zip(t, sun.azimuth, sun.elevation):
            if el > 5:
                rows.append((ti, az + rng.normal(0, 0.05), el + rng.normal(0, 0.05)))
    with open(HERE / "observations.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time", "az_deg", "el_deg", "sigma_deg"])
        for ti, az, el in rows:
            w.writerow(
                [
                    datetime.fromtimestamp(ti, UTC).strftime("%Y-%m-%dT%H:%M:%SZ"),
                    f"{az:.4f}",
                    f"{el:.4f}",
                    "0.05",
                ]
            )


def irradiance() -> None:
    from hil.sky import sky_series

    t0 = datetime(2024, 3, 20, tzinfo=UTC).timestamp() - LON / 15 * 3600  # local mean midnight
    t = t0 + np.arange(4 * 1440) * 60.0
    sky = sky_series(t, LAT, LON, ALT, {0: "clear", 1: "partly-cloudy", 2: "overcast", 3: "clear"}, seed=7)
    with open(HERE / "irradiance.csv", "w", newline="") as f:
        w = csv.writer(f)
        w.writerow(["time_utc", "ghi_w_m2", "dni_w_m2"])
        for ti, g, d in zip(t, sky.ghi, sky.dni):
            w.writerow(
                [datetime.fromtimestamp(ti, UTC).strftime("%Y-%m-%dT%H:%M:%SZ"), f"{g:.1f}", f"{d:.1f}"]
            )


if __name__ == "__main__":
    observations()
    irradiance()
    frames()
    print(f"wrote {HERE}")
