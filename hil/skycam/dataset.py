"""Write what an installer of the sky camera would collect, rendered by the HIL world:

    OUT/checkerboards/board_NN.png        lens-calibration views (grey)
    OUT/day/<YYYY-MM-DDTHH-MM-SSZ>.png    a clear day of sky frames every ``step_min`` minutes
                                          (the canonical file-name time form)
    OUT/horizon.png                       a clear frame for levelling from the horizon
    OUT/truth.json                        the world's truth, for evaluation only

Usage: ``python -m hil.skycam.dataset OUT [--profile seed|hd] [--site NAME] [--no-noise]``.
"""

from __future__ import annotations

import argparse
import json
from datetime import UTC, datetime
from pathlib import Path

import cv2
import numpy as np

from .checkerboard import checkerboard_poses, render_checkerboard
from .render import render_sky
from .scene import PROFILES, SITES, SkyScene, sky_profile


def frame_name(t: float, suffix: str = ".png") -> str:
    """The canonical file name of a frame taken at POSIX ``t`` (``2026-03-20T10-15-00Z.png``)."""
    return datetime.fromtimestamp(float(t), UTC).strftime("%Y-%m-%dT%H-%M-%SZ") + suffix


def write_dataset(
    scn: SkyScene,
    out: Path,
    *,
    day: tuple[int, int, int] = (2025, 3, 20),
    step_min: int = 15,
    n_boards: int = 30,
    seed: int = 11,
    min_el_deg: float = 5.0,
) -> dict:
    """Render the installer's folder; returns the truth written to ``truth.json``."""
    out = Path(out)
    rng = np.random.default_rng(seed)
    (out / "checkerboards").mkdir(parents=True, exist_ok=True)
    (out / "day").mkdir(exist_ok=True)
    lens = scn.lens
    for k, (rv, tv) in enumerate(checkerboard_poses(lens, n_boards, rng, max_theta_deg=80.0)):
        cv2.imwrite(
            str(out / "checkerboards" / f"board_{k:02d}.png"), render_checkerboard(lens, rv, tv, rng=rng)
        )
    t0 = datetime(day[0], day[1], day[2], tzinfo=UTC).timestamp()
    ts = t0 + np.arange(0, 86400, step_min * 60)
    sun = scn.sun(ts)
    frames = []
    for t, az, el in zip(ts, sun["azimuth"], sun["elevation"]):
        if el < min_el_deg:
            continue
        fr = render_sky(scn, float(t), rng=rng, sun=(float(az), float(el)))
        name = frame_name(float(t))
        cv2.imwrite(str(out / "day" / name), fr.image)
        frames.append({"image": f"day/{name}", "az_deg": float(az), "el_deg": float(el)})
    noon = float(ts[int(np.argmax(sun["elevation"]))])
    cv2.imwrite(str(out / "horizon.png"), render_sky(scn, noon, rng=rng).image)
    truth = {
        "profile": scn.name,
        "lens": {
            "width": lens.width,
            "height": lens.height,
            "fx": lens.fx,
            "fy": lens.fy,
            "cx": lens.cx,
            "cy": lens.cy,
            "D": list(lens.D),
            "fov_deg": lens.fov_deg,
        },
        "enu_from_camera": [list(r) for r in scn.enu_from_camera],
        "site": {
            "latitude": scn.site.latitude,
            "longitude": scn.site.longitude,
            "altitude": scn.site.altitude,
        },
        "frames": frames,
    }
    (out / "truth.json").write_text(json.dumps(truth, indent=1))
    return truth


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m hil.skycam.dataset", description=__doc__.split("\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--profile", default="seed", choices=PROFILES)
    ap.add_argument("--site", default="andimeshk", choices=sorted(SITES))
    ap.add_argument("--step-min", type=int, default=15)
    ap.add_argument("--no-noise", action="store_true")
    a = ap.parse_args(argv)
    scn = sky_profile(a.profile, noise=not a.no_noise, site=SITES[a.site])
    write_dataset(scn, a.out, step_min=a.step_min)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
