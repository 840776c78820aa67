"""Recording the world's camera frames (``heliotrack hil record``).

The frames are rendered exactly as ``simulate`` renders them for the controller: the same
renderer (:mod:`heliotrack.renderers`), the same clouds (the scenario's sky, computed one
day at a time on the same sample grid), at the control cycles' times.  So a recorded day
replayed by ``heliotrack replay`` sees the frames the live simulation saw.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from tqdm import tqdm

from controller.config import Config
from controller.errors import ConfigError, InputError
from controller.sun.camera import IMAGE_SUFFIXES
from controller.timestamps import format_name_time, to_iso

from .recorded_truth import SKY_COLUMNS, TRUTH_COLUMNS, TRUTH_FILE, truth_row
from .renderers import camera_sensor, world_renderer
from .scenario import as_scenario
from .scoring import truth_grid
from .simulate import Span, cycles_per_day, day_samples, world_truth

#: Frames with the true sun lower than this are skipped (the controller does not look).
NIGHT_ELEVATION_DEG = -8.0


@dataclass
class Recorded:
    frames: int = 0
    visible: int = 0
    first: str = ""
    last: str = ""
    every_s: float = 0.0
    interrupted: bool = False


def record_frames(
    config: Config,
    span: Span,
    out: Path,
    *,
    every_s: float | None = None,
    night: bool = False,
    fmt: str = "png",
    progress: bool = False,
) -> Recorded:
    """Render the configured camera's frames over ``span`` into ``out`` with ``truth.csv``.

    ``every_s``: time between frames (default the control period: the controller's own
    cadence, which replays exactly).  ``night``: also frames with the sun below
    :data:`NIGHT_ELEVATION_DEG`.  ``fmt``: ``png`` (lossless) or ``jpg`` (quality 95).
    Ctrl-C stops cleanly: every frame written is listed in ``truth.csv``.
    """
    import csv

    scenario = as_scenario(config)
    if camera_sensor(scenario) is None:
        raise ConfigError(
            scenario.file,
            "control.sun_source",
            'a camera sensor whose frames the world renders (e.g. "hotspot")',
            scenario.control.sun_source,
        )
    out = Path(out)
    taken = [p.name for p in out.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES or p.name == TRUTH_FILE]
    if taken:
        raise InputError(
            f"--out: {out} already holds frames or a truth.csv ({taken[0]}, ...): give a new or empty folder"
        )
    period = scenario.control.period_s
    every = float(every_s or period)
    seconds = span.n_cycles * period
    times = span.t0 + np.arange(math.ceil(seconds / every - 1e-9)) * every
    truth = world_truth(scenario)
    day_len = cycles_per_day(period) * period
    result = Recorded(every_s=every)
    grid = None

    def transmittance(t: float) -> float:
        assert grid is not None
        return float(np.interp(t, grid.t, grid.sky.beam_transmittance))

    render = world_renderer(scenario, transmittance)
    assert render is not None
    suffix = ".jpg" if fmt == "jpg" else ".png"
    params = [cv2.IMWRITE_JPEG_QUALITY, 95] if fmt == "jpg" else []
    bar = tqdm(total=times.size, desc="hil record", unit="frame", disable=not progress, leave=False)
    with open(out / TRUTH_FILE, "w", newline="") as f:
        writer = csv.DictWriter(f, fieldnames=TRUTH_COLUMNS, extrasaction="ignore")
        writer.writeheader()
        try:
            for day in range(int((times[-1] - span.t0) // day_len) + 1 if times.size else 0):
                in_day = times[(times >= span.t0 + day * day_len) & (times < span.t0 + (day + 1) * day_len)]
                if in_day.size == 0:
                    continue
                _, samples = day_samples(span, period, scenario.hil.substeps, day)
                grid = truth_grid(truth, samples, day)
                sun = truth.sun(in_day)
                sky = {
                    "ghi_w_m2": np.interp(in_day, grid.t, grid.sky.ghi),
                    "dni_w_m2": np.interp(in_day, grid.t, grid.sky.dni),
                    "dhi_w_m2": np.interp(in_day, grid.t, grid.sky.dhi),
                    "beam_transmittance": np.interp(in_day, grid.t, grid.sky.beam_transmittance),
                }
                for k, t in enumerate(in_day):
                    bar.update(1)
                    el = float(sun.elevation[k])
                    if el < NIGHT_ELEVATION_DEG and not night:
                        continue
                    name = format_name_time(round(float(t), 3)) + suffix
                    if not cv2.imwrite(str(out / name), render(float(t)), params):
                        raise InputError(f"--out: cannot write {out / name}")
                    row = truth_row(
                        float(t), name, float(sun.azimuth[k]), el, {c: float(sky[c][k]) for c in SKY_COLUMNS}
                    )
                    writer.writerow(row)
                    f.flush()
                    result.frames += 1
                    result.visible += row["sun_visible"]
                    result.first = result.first or to_iso(float(t))
                    result.last = to_iso(float(t))
        except KeyboardInterrupt:
            result.interrupted = True
        finally:
            bar.close()
    return result
