"""The sun-path benchmark's data seen through the project's own hotspot sensor.

The synthetic benchmark adds Gaussian noise to SPA positions.  Here the same sample times
and the same cloud gaps go through the HIL instead: the world's camera renders the glint on
the convex surface at each time (``hil.camera.render_frame``, a thick cloud where the
synthetic data has a gap), and the controller's estimator turns each frame into a
:class:`SunObservation` with the calibration bundle the loop uses (``HotspotEstimator``,
the object ``heliotrack simulate`` wires in for ``sun_source = "hotspot"``).  Frames where
the sensor finds nothing are simply missing, as in the loop.  The resulting
:class:`~benchmarks.sunpath.Dataset` feeds both sun-path methods unchanged.

Rendering is the cost (about 0.3 s a frame), so frames are rendered in a process pool.
"""

from __future__ import annotations

import multiprocessing
import os
from concurrent.futures import ProcessPoolExecutor
from dataclasses import replace
from pathlib import Path

import numpy as np

#: Beam transmittance of the benchmark's cloud gaps (thick cloud: the sun is hidden).
CLOUD_TRANSMITTANCE = 0.02
#: The loop's camera: the recommended profile, its base tilted 0.3 deg and calibrated from
#: rendered images alone (config/hil-hotspot.toml).
PROFILE = "recommended"
TILT_DEG = 0.3
BUNDLE = Path(__file__).resolve().parents[1] / "config" / "calibration" / "recommended.toml"

_THREAD_VARS = ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")
_worker: dict = {}


def _init(site: tuple[float, float, float], profile_name: str, tilt_deg: float, bundle: str) -> None:
    import cv2

    from controller.calibration.bundle import load_bundle
    from controller.vision import HotspotEstimator
    from hil.camera import Site as CameraSite
    from hil.camera import profile

    cv2.setNumThreads(1)  # one frame per process: threads inside would only contend

    _worker["scn"] = profile(profile_name, noise=True, tilt_deg=tilt_deg).with_(site=CameraSite(*site))
    _worker["est"] = HotspotEstimator(load_bundle(bundle), algorithm="default")


def _observe(job: tuple[float, float]) -> tuple[float, float, float, str]:
    """(az, el, sigma, reason) of one rendered frame; nan and the reason when not found."""
    from hil.camera import render_frame

    t, tau = job
    img = render_frame(_worker["scn"], t, transmittance=tau).image
    obs = _worker["est"].estimate_image(img, t)
    o = obs.observation()
    if o is None:
        return np.nan, np.nan, np.nan, obs.reason or "not found"
    return o.az_deg, o.el_deg, o.sigma_deg, ""


def hotspot_dataset(
    ds,
    workers: int | None = None,
    profile_name: str = PROFILE,
    tilt_deg: float = TILT_DEG,
    bundle: Path = BUNDLE,
):
    """``ds`` re-observed by the hotspot sensor: same times, same cloud gaps.

    Returns the new dataset and a count of why frames gave no observation.
    """
    site = (ds.site.latitude, ds.site.longitude, ds.site.altitude)
    jobs = [(float(t), 1.0 if c else CLOUD_TRANSMITTANCE) for t, c in zip(ds.t, ds.clear)]
    workers = workers or max(1, os.cpu_count() or 1)
    # Spawned workers with single-threaded BLAS: the pool is the parallelism.
    saved = {k: os.environ.get(k) for k in _THREAD_VARS}
    os.environ.update({k: "1" for k in _THREAD_VARS})
    try:
        with ProcessPoolExecutor(
            workers,
            mp_context=multiprocessing.get_context("spawn"),
            initializer=_init,
            initargs=(site, profile_name, tilt_deg, str(bundle)),
        ) as pool:
            out = list(pool.map(_observe, jobs, chunksize=16))
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    az = np.array([o[0] for o in out])
    el = np.array([o[1] for o in out])
    sig = np.array([o[2] for o in out])
    found = np.isfinite(el)
    reasons: dict[str, int] = {}
    for (_, _, _, why), c in zip(out, ds.clear):
        if why:
            key = f"{'clear' if c else 'cloud'}: {why}"
            reasons[key] = reasons.get(key, 0) + 1
    hds = replace(
        ds,
        az_obs=np.where(found, az % 360.0, 0.0),
        el_obs=np.where(found, el, 0.0),
        clear=found,
        sigma=np.where(found, sig, 1.0),
        sensor="hotspot",
    )
    return hds, reasons


def sensor_errors(hds) -> dict:
    """Angular error of the hotspot observations against SPA (deg)."""
    from controller.sun.types import angle_between_deg, azel_to_enu

    m = hds.clear
    err = angle_between_deg(
        azel_to_enu(hds.az_obs[m], hds.el_obs[m]), azel_to_enu(hds.az_true[m], hds.el_true[m])
    )
    return {
        "n": int(m.sum()),
        "rms_deg": float(np.sqrt(np.mean(err**2))),
        "p95_deg": float(np.percentile(err, 95)),
        "max_deg": float(err.max()),
        "el_error_mean_deg": float(np.mean(hds.el_obs[m] - hds.el_true[m])),
        "sigma_reported_median_deg": float(np.median(hds.sigma[m])),
    }


#: The paper's five consecutive days (Table 3: 8-12 Farvardin 1403), with cloud on two.
LOOP_START = "2024-03-27"
LOOP_SKIES = ("clear", "partly-cloudy", "clear", "partly-cloudy", "clear")


def hil_loop(days: int = len(LOOP_SKIES), interval_s: float = 900.0) -> dict:
    """``heliotrack simulate`` on config/hil-hotspot.toml with the site unknown to the filter.

    The paper's sampling (one frame per ``interval_s``) while the controller sends a
    setpoint every minute: between frames and through clouds the sun-path filter predicts.
    Until the filter has started (12 observations over 3 h on day 1) the estimate is the
    last two frames extrapolated; before the first two frames the trackers stay in stow.
    """
    import tomllib
    from datetime import date

    from heliotrack.scenario import parse_scenario
    from heliotrack.simulate import run_simulation

    path = Path(__file__).resolve().parents[1] / "config" / "hil-hotspot.toml"
    data = tomllib.loads(path.read_text())
    data["hotspot"]["interval_s"] = interval_s
    data["sunpath"]["site_known"] = False
    data["hil"]["sky"] = list(LOOP_SKIES[:days])
    cfg = parse_scenario(data, path)
    s = run_simulation(cfg, days=days, start=date.fromisoformat(LOOP_START), progress=False)
    return {
        "config": "config/hil-hotspot.toml with [hotspot] interval_s = "
        f"{interval_s:g} and [sunpath] site_known = false",
        "start": LOOP_START,
        "days": days,
        "skies": list(LOOP_SKIES[:days]),
        "control_period_s": s["control_period_s"],
        "wall_s": s["wall_s"],
        "pointing_error_deg": s["pointing_error_deg"],
        "energy_ratio": s["energy_ratio"],
        "trackers": s["trackers"],
        "modes_tracker_cycles": s["modes"],
        "sources_tracker_cycles": s["sources"],
        "camera_frames": s.get("camera_frames"),
        "sun_path_learned": s.get("sun_path"),
        "modbus": s["modbus"],
    }
