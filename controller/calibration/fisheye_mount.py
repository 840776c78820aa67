"""A panel camera's rotation on its panel, from its sun sightings and the panel's true angles.

The panel-mounted closed loop puts the sun on the camera's axis and learns whatever that
leaves as the row's offset, so a camera mounted 0.5 deg off the panel's normal points the
panel 0.5 deg off the sun, and nothing in the loop can see it.  With the panel's true
angles known at each frame (an inclinometer on the panel for a row's rotation or a
panel's elevation; a survey, or the drive's homed encoder, for an azimuth), the ephemeris
gives the sun in the panel's frame, ``s_i``, and the camera measures it in its own, ``d_i``.
The mount ``M`` (``panel_from_camera``) minimises ``sum |M d_i - s_i|^2``.

Frames of a panel that tracks the sun all see it near the camera's axis, and the rotation
about that axis is then unobservable.  So the fit is Gauss-Newton on a rotation vector,
from Kabsch's rotation, with a weak prior towards the identity (ridge ``PRIOR_DEG``): a
direction the sightings do not constrain goes where an exactly mounted camera has it, and
its sigma says so.
Holding the panel at a few fixed angles while the sun moves across the image (stow, and
angles 20-40 deg either side) fixes all three.

Angles in degrees; vectors are unit 3-vectors; the panel's frame is
:mod:`controller.closedloop.geometry`'s (z the normal, x towards increasing azimuth or
rotation).
"""

from __future__ import annotations

import csv
import io
import math
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from ..closedloop.geometry import dual_axis_enu_from_camera, row_enu_from_camera
from ..errors import InputError
from .fisheye_orientation import kabsch

#: The prior's sigma on each component of the mount's rotation vector (deg): far wider than
#: any mount a jig leaves, so that it only decides what the sightings leave undecided.
PRIOR_DEG = 20.0
#: A sighting's nominal error (deg) for weighing the prior in the fit.
SIGHTING_DEG = 0.05
#: A component whose sigma is over this (deg) is reported as not determined by the sightings.
UNDETERMINED_DEG = 0.5
#: A mount this far from the panel's normal is not a camera on that panel (deg): the panel's
#: angles, the site or the frames' times are wrong.
MAX_MOUNT_DEG = 10.0


def _cross_rows(p: np.ndarray) -> np.ndarray:
    """``-[p_i]x`` stacked (3N x 3): the derivative of ``exp(w) p_i`` by ``w`` at 0."""
    x, y, z = p[:, 0], p[:, 1], p[:, 2]
    o = np.zeros_like(x)
    blocks = np.stack([np.stack([o, z, -y], 1), np.stack([-z, o, x], 1), np.stack([y, -x, o], 1)], 1)
    return blocks.reshape(-1, 3)


@dataclass(frozen=True)
class MountFit:
    """The fitted mount.

    ``panel_from_camera``: 3 x 3 (d_panel = M d_cam); ``rotvec_deg``: the same as a rotation
    vector in the panel's frame; ``axis_off_deg``: the angle between the camera's axis and
    the panel's normal; ``residual_deg``: RMS angle between ``M d_i`` and ``s_i``;
    ``sigma_deg``: each rotation-vector component's standard error (deg);
    ``determined``: per component, whether the sightings decide it; ``used``: sightings.
    """

    panel_from_camera: np.ndarray
    rotvec_deg: np.ndarray
    axis_off_deg: float
    residual_deg: float
    sigma_deg: np.ndarray
    determined: tuple[bool, bool, bool]
    used: int


def panel_frame(
    kind: str, angles: Sequence[float], axis_azimuth: float = 180.0, axis_tilt: float = 0.0
) -> np.ndarray:
    """``enu_from_panel`` of a panel at its true ``angles`` (deg): dual-axis ``[azimuth,
    elevation]``, single-axis ``[rotation]`` about a row at ``axis_azimuth``/``axis_tilt``."""
    if kind == "dual-axis":
        return dual_axis_enu_from_camera(float(angles[0]), float(angles[1]))
    return row_enu_from_camera(float(angles[0]), axis_azimuth, axis_tilt)


def _angles_deg(M: np.ndarray, d: np.ndarray, s: np.ndarray) -> np.ndarray:
    return np.degrees(np.arccos(np.clip(np.sum((d @ M.T) * s, axis=1), -1.0, 1.0)))


def fit_mount(
    d_cam: np.ndarray, s_panel: np.ndarray, sigma_deg: np.ndarray | None = None, *, iterations: int = 20
) -> MountFit:
    """The mount ``M`` minimising ``sum |M d_i - s_i|^2 / sigma_i^2`` (camera-frame sightings
    ``d_cam``, the ephemeris's sun in the panel's frame ``s_panel``; N x 3 each; each
    sighting's one-sigma ``sigma_deg``, the pipeline's, None: equal).  A sun near the image
    circle's edge is read less well than one near the axis, and says so in its sigma.

    Raises
    ------
    InputError
        Fewer than 3 sightings, or a mount more than :data:`MAX_MOUNT_DEG` off the normal.
    """
    d = np.asarray(d_cam, float).reshape(-1, 3)
    s = np.asarray(s_panel, float).reshape(-1, 3)
    if len(d) < 3:
        raise InputError(f"mount: {len(d)} sighting(s) of the sun, need at least 3")
    d = d / np.linalg.norm(d, axis=1, keepdims=True)
    s = s / np.linalg.norm(s, axis=1, keepdims=True)
    sig = (
        np.full(len(d), SIGHTING_DEG)
        if sigma_deg is None
        else np.maximum(np.asarray(sigma_deg, float), 0.005)
    )
    wt = np.repeat((SIGHTING_DEG / sig) ** 2, 3)  # per residual component, 1 at SIGHTING_DEG
    lam = (SIGHTING_DEG / PRIOR_DEG) ** 2
    # start from Kabsch's rotation: a camera turned a half turn on its panel (mounted upside
    # down) lies where Gauss-Newton from the identity does not reach; where the sightings
    # leave a direction free, the prior below moves it back towards the identity
    w = Rotation.from_matrix(kabsch(d, s, wt[::3])).as_rotvec()
    for _ in range(iterations):
        R = Rotation.from_rotvec(w)
        p = d @ R.as_matrix().T  # M d_i
        J = _cross_rows(p)
        Jw = J * wt[:, None]
        step = np.linalg.solve(Jw.T @ J + lam * np.eye(3), Jw.T @ (s - p).reshape(-1) - lam * w)
        w = (Rotation.from_rotvec(step) * R).as_rotvec()
        if np.linalg.norm(step) < 1e-10:
            break
    M = Rotation.from_rotvec(w).as_matrix()
    err = _angles_deg(M, d, s)
    residual = float(np.sqrt(np.mean(err**2)))
    # each component's posterior sigma: the sightings at their weighted scatter (per
    # component of the residual vector; a noise-free fit still has its pixels) and the prior
    wmean = float(np.mean(wt[::3]))
    noise = math.radians(max(float(np.sqrt(np.mean(err**2 * wt[::3]) / wmean)), 0.005)) / math.sqrt(2.0)
    J = _cross_rows(d @ M.T)
    info = (J * (wt / wmean)[:, None]).T @ J / noise**2 + np.eye(3) / math.radians(PRIOR_DEG) ** 2
    sigma = np.degrees(np.sqrt(np.diag(np.linalg.inv(info))))
    determined = tuple(bool(x <= UNDETERMINED_DEG) for x in sigma)
    axis_off = float(np.degrees(np.arccos(np.clip(M[2, 2], -1.0, 1.0))))
    if axis_off > MAX_MOUNT_DEG:
        raise InputError(
            f"mount: the fit puts the camera's axis {axis_off:.1f} deg off the panel's normal (over "
            f"{MAX_MOUNT_DEG:g}): the panel's angles, the site or the frames' times are wrong"
        )
    return MountFit(
        panel_from_camera=M,
        rotvec_deg=np.degrees(w),
        axis_off_deg=axis_off,
        residual_deg=residual,
        sigma_deg=sigma,
        determined=determined,  # type: ignore[arg-type]
        used=len(d),
    )


def read_panel_angles(path: str | Path, axes: Sequence[str]) -> list[tuple[float, list[float]]]:
    """The panel's true angles over time from a CSV: a ``time`` column (with a zone) and one
    column per axis (``rotation``; or ``azimuth`` and ``elevation``), in deg; time-sorted.

    Raises
    ------
    InputError
        A missing file or column, or a bad value (names the file, row and column).
    """
    from ..sunpath.io import parse_time, read_text_strict

    path = Path(path)
    text = read_text_strict(path, "panel angles")
    reader = csv.DictReader(io.StringIO(text, newline=""))
    header = [h.strip() for h in (reader.fieldnames or [])]
    reader.fieldnames = header
    missing = [c for c in ("time", *axes) if c not in header]
    if missing:
        raise InputError(
            f"{path}: row 1 (header): missing column(s) {', '.join(missing)}; expected time, "
            f"{', '.join(axes)} (deg, the panel's true angles), got {', '.join(header) or 'nothing'}"
        )
    out = []
    for row_no, row in enumerate(reader, start=2):
        w = f"{path}: row {row_no}"
        if row.get(None):
            raise InputError(f"{w}: more fields than the header names (a decimal comma? use a point)")
        if not any((v or "").strip() for v in row.values() if isinstance(v, str)):
            continue
        t = parse_time(row.get("time") or "", f"{w}, column 'time'")
        angles = []
        for ax in axes:
            text_v = (row.get(ax) or "").strip()
            try:
                v = float(text_v)
            except ValueError:
                v = math.nan
            if not (math.isfinite(v) and -360.0 <= v <= 360.0):
                raise InputError(f"{w}, column '{ax}': expected an angle in degrees, got {text_v!r}")
            angles.append(v)
        out.append((t, angles))
    if not out:
        raise InputError(f"{path}: no rows (expected time, {', '.join(axes)})")
    return sorted(out, key=lambda r: r[0])


def angles_at(readings: list[tuple[float, list[float]]], t: float, max_gap_s: float) -> list[float] | None:
    """The reading nearest ``t`` (POSIX s), or None when none is within ``max_gap_s``."""
    best = min(readings, key=lambda r: abs(r[0] - t))
    return best[1] if abs(best[0] - t) <= max_gap_s else None
