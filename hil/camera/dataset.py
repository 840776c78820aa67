"""Write what an installer would collect, rendered by the HIL world, for the calibration chain:

    OUT/checkerboards/board_NN.png   intrinsics views (installed camera, board held in front)
    OUT/globe_scan.ply               the surface's 3-D scan (SfM stand-in: points, no normals,
                                     0.2 mm noise) of the REAL (possibly bumpy) globe
    OUT/markers_survey.csv           marker corners from the scan (id, corner, x, y, z; 0.3 mm noise)
    OUT/marker_view.png              installed camera's view of the base markers
    OUT/plumb_view.png               installed camera's view with plumb strings hung in it
    OUT/day/frame_<ISO>.png          a clear day of frames every ``step_min`` minutes
    OUT/truth.json                   the world's truth, for evaluation only (never for calibration)

Usage: ``python -m hil.camera.dataset OUT [--profile recommended|seed] [--no-noise]``.
"""

from __future__ import annotations

import argparse
import json
from datetime import UTC, datetime
from pathlib import Path

import cv2
import numpy as np

from .render import render_frame
from .scene import Scenario, profile
from .views import checkerboard_poses, render_checkerboard, render_marker_view, render_plumb_view


def write_dataset(
    scn: Scenario,
    out: Path,
    *,
    day=(2025, 3, 20),
    step_min: int = 15,
    n_boards: int = 12,
    seed: int = 11,
    scan_points: int = 60000,
) -> dict:
    out = Path(out)
    rng = np.random.default_rng(seed)
    (out / "checkerboards").mkdir(parents=True, exist_ok=True)
    (out / "day").mkdir(exist_ok=True)
    cam = scn.camera
    for k, (rv, tv) in enumerate(checkerboard_poses(cam, n_boards, rng)):
        img = render_checkerboard(cam, rv, tv, rng=rng)
        cv2.imwrite(str(out / "checkerboards" / f"board_{k:02d}.png"), img)
    pts, _ = scn.globe.surface_points(scan_points, rng)
    pts = pts + rng.normal(0, 0.0002, pts.shape)
    with open(out / "globe_scan.ply", "w") as f:
        f.write(
            f"ply\nformat ascii 1.0\nelement vertex {len(pts)}\nproperty float x\n"
            "property float y\nproperty float z\nend_header\n"
        )
        np.savetxt(f, pts, fmt="%.6f")
    with open(out / "markers_survey.csv", "w") as f:
        f.write("id,corner,x,y,z\n")
        for mid, k, x, y, z in scn.base.marker_table():
            e = rng.normal(0, 0.0003, 3)
            f.write(f"{mid},{k},{x + e[0]:.6f},{y + e[1]:.6f},{z + e[2]:.6f}\n")
    y, mo, d = day
    t_mid = datetime(y, mo, d, 6, 30, tzinfo=UTC).timestamp()
    cv2.imwrite(str(out / "marker_view.png"), render_marker_view(scn, t_mid, rng).image)
    cv2.imwrite(str(out / "plumb_view.png"), render_plumb_view(scn, t_mid, rng=rng).image)
    t0 = datetime(y, mo, d, tzinfo=UTC).timestamp()
    ts = t0 + np.arange(0, 86400, step_min * 60)
    sun = scn.sun(ts)
    frames = []
    for t, el in zip(ts, sun["elevation"]):
        if el < 5:
            continue
        name = datetime.fromtimestamp(float(t), UTC).strftime("frame_%Y-%m-%dT%H-%M-%SZ.png")
        fr = render_frame(scn, float(t), rng=rng)
        cv2.imwrite(str(out / "day" / name), fr.image)
        frames.append({"image": f"day/{name}", "az_deg": fr.truth["az_deg"], "el_deg": fr.truth["el_deg"]})
    truth = {
        "profile": scn.name,
        "camera": {"fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy, "dist": list(cam.dist)},
        "rvec": scn.pose.rvec.tolist(),
        "tvec": scn.pose.tvec.tolist(),
        "zenith_model": scn.zenith_model.tolist(),
        "globe_radius": scn.globe.radius,
        "site": {"lat": scn.site.latitude, "lon": scn.site.longitude},
        "frames": frames,
    }
    (out / "truth.json").write_text(json.dumps(truth, indent=1))
    return truth


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m hil.camera.dataset", description=__doc__.split("\n")[0])
    ap.add_argument("out", type=Path)
    ap.add_argument("--profile", default="recommended", choices=("recommended", "seed"))
    ap.add_argument("--no-noise", action="store_true")
    ap.add_argument("--bumps-mm", type=float, default=0.0, help="shape imperfection amplitude")
    ap.add_argument("--tilt-deg", type=float, default=0.3, help="base not level by this much")
    a = ap.parse_args(argv)
    scn = profile(a.profile, noise=not a.no_noise, tilt_deg=a.tilt_deg)
    if a.bumps_mm:
        scn = scn.with_(globe=scn.globe.__class__(bump_amplitude_m=a.bumps_mm / 1000))
    write_dataset(scn, a.out)
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":  # pragma: no cover
    raise SystemExit(main())
