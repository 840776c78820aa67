"""A second sky renderer, written apart from ``hil/skycam``, to check the default fisheye
pipeline on frames the HIL world did not make (issue 14: "a different lens, glare profile,
smear and cloud model").  It shares no code with ``hil/skycam``; every model differs:

* **lens**: an exact equisolid-angle projection ``r = 2 f sin(theta / 2)`` (not Kannala-
  Brandt); the pipeline is handed a ``cv2.fisheye`` fit of it, as a calibration would give;
* **sky**: the CIE standard clear sky (ISO 15469 type 12) luminance distribution, a blue
  that whitens towards the sun and the horizon, a flat dark ground; other looks take other
  CIE general sky types or a power-law aureole (:mod:`benchmarks.fisheye_other_sky`);
* **glare**: an exponential aureole plus a power-law wing on the sky, and a Lorentzian
  veiling glare round on the sensor, mixed 60 / 40; another look draws it as a simple
  renderer would, a hard-edged saturated disk and an exponential halo;
* **smear**: bloom that spills *upwards only* (one-sided, as on sensors read one way);
* **sensor**: vignetting ``1 - 0.25 (r / r_max)^2``, Poisson-Gaussian noise of a 10 000 e-
  well, the sRGB tone curve, JPEG q85; other looks: linear output, gamma 2.2, a filmic
  S-curve that rolls the highlights off (with a Gaussian aureole), Gaussian noise added
  to the output (so the saturated plateau is noisy too); the pipeline's bundle declares
  the camera's response and vignetting (:func:`radiometry`) except in one look;
* **clouds**: drifting elliptical Gaussian puffs of optical depth 2-12, sunlit (forward
  scattering) next to the sun; the sun is visible where the puffs' summed depth along its
  line of sight is under 0.1, hidden where nothing of it saturates any more (its peak
  through the cloud under full scale), dimmed in between.

Truth: pvlib's SPA apparent elevation and azimuth, directly.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace

import cv2
import numpy as np

from .fisheye_other_sky import SAME_LEVEL, SKIES, cie_clear

THETA_MAX = math.radians(95.0)


@dataclass(frozen=True)
class Sensor:
    """The camera's pixels behind the equisolid lens (``r = 2 f sin(theta / 2)``, px)."""

    width: int = 640
    height: int = 480
    f_eq: float = 150.0
    cx: float = 321.3
    cy: float = 238.1

    def scaled(self, k: float) -> Sensor:
        """The same lens and field on pixels ``k`` times finer (1280 x 960 for ``k`` = 2)."""
        return Sensor(
            round(self.width * k),
            round(self.height * k),
            self.f_eq * k,
            (self.cx + 0.5) * k - 0.5,
            (self.cy + 0.5) * k - 0.5,
        )


SENSOR = Sensor()
SITE = (36.75, -4.42, 20.0)  # Malaga: another latitude, west of Greenwich


@dataclass
class OtherLook:
    """One look of the second renderer (all optional parts off by default)."""

    name: str
    veil_weight: float = 0.4  # share of the glare round on the sensor
    sat_radius_deg: float = 3.0  # saturated radius, zenith sun, clear sky
    bloom: float = 0.0  # upward spill, in saturated radii
    jpeg: int | None = 85
    clouds: list = field(default_factory=list)  # [(az, el, sx_deg, sy_deg, tau, (vaz, vel) deg/min)]
    sun: bool = True  # False: the sky alone (for diagnosis)
    noise: bool = True
    sky: str = "cie"  # "flat": a uniform sky (for diagnosis); "dome": a flat field (all the view)
    sky_type: int | str = 12  # a key of CIE_SKY_TYPES, or "power" (see cie_clear)
    sky_level: float = 1.0  # the sky's luminance, relative to the camera's exposure for type 12
    vignetting: float = 0.25
    tone: str = "srgb"  # "gamma2.2", "filmic" (an S-curve over gamma 2.2) or "linear"
    aureole: str = "exp"  # "gauss": a Gaussian core (1.6 deg) and a power-law wing; "disk": a
    # hard-edged saturated disk of sat_radius_deg and a halo of 0.7 full scale at its edge
    # falling by e every 1.5 deg (as a simple renderer draws the sun; veil_weight ignored)
    post_noise: float = 0.0  # grey levels of Gaussian noise added after the clip and tone
    radiometry: str = "exact"  # the bundle's [radiometry]: "exact", "calibrated" or "none"
    exposure: float = 1.0  # relative exposure (brackets for the response's calibration)
    turned: bool = False  # the frame turned 90 deg: a sensor read out across the stored image


def kb_fit(sensor: Sensor = SENSOR) -> tuple[np.ndarray, np.ndarray]:
    """``cv2.fisheye`` K and D of the equisolid lens (theta_d = 2 sin(theta / 2))."""
    th = np.linspace(1e-3, THETA_MAX, 400)
    td = 2.0 * np.sin(th / 2.0)
    A = np.stack([th**3, th**5, th**7, th**9], 1)
    D, *_ = np.linalg.lstsq(A, td - th, rcond=None)
    K = np.array([[sensor.f_eq, 0, sensor.cx], [0, sensor.f_eq, sensor.cy], [0, 0, 1.0]])
    return K, D


def rotation(yaw_deg: float = 25.0, tilt_deg: float = 2.0, tilt_az_deg: float = 100.0) -> np.ndarray:
    """``enu_from_camera`` (columns: camera x, y, z in ENU) of a zenith camera, yawed then tilted."""
    y = math.radians(yaw_deg)
    x_c = np.array([math.cos(y), -math.sin(y), 0.0])
    z_c = np.array([0.0, 0.0, 1.0])
    R = np.column_stack([x_c, np.cross(z_c, x_c), z_c])
    a, t = math.radians(tilt_az_deg), math.radians(tilt_deg)
    k = np.array([math.cos(a), -math.sin(a), 0.0])  # horizontal axis across the tilt
    Kx = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    Rt = np.eye(3) + math.sin(-t) * Kx + (1 - math.cos(t)) * Kx @ Kx
    return Rt @ R


def pixel_rays(sensor: Sensor = SENSOR) -> tuple[np.ndarray, np.ndarray]:
    """Camera-frame unit direction of every pixel (H, W, 3) and the image-circle mask."""
    u, v = np.meshgrid(np.arange(sensor.width, dtype=np.float64), np.arange(sensor.height, dtype=np.float64))
    r = np.hypot(u - sensor.cx, v - sensor.cy)
    s = np.clip(r / (2 * sensor.f_eq), 0, 1)
    th = 2 * np.arcsin(s)
    ph = np.arctan2(v - sensor.cy, u - sensor.cx)
    d = np.stack([np.sin(th) * np.cos(ph), np.sin(th) * np.sin(ph), np.cos(th)], -1)
    return d, th <= THETA_MAX


def project(d_cam: np.ndarray, sensor: Sensor = SENSOR) -> tuple[float, float]:
    th = math.acos(max(-1.0, min(1.0, float(d_cam[2]))))
    ph = math.atan2(float(d_cam[1]), float(d_cam[0]))
    r = 2 * sensor.f_eq * math.sin(th / 2)
    return sensor.cx + r * math.cos(ph), sensor.cy + r * math.sin(ph)


def sun_truth(ts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    import pandas as pd
    import pvlib

    sp = pvlib.solarposition.get_solarposition(
        pd.DatetimeIndex(pd.to_datetime(ts, unit="s", utc=True)), SITE[0], SITE[1], altitude=SITE[2]
    )
    return sp["azimuth"].to_numpy(), sp["apparent_elevation"].to_numpy()


def enu(az_deg, el_deg) -> np.ndarray:
    az, el = np.radians(az_deg), np.radians(el_deg)
    return np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], -1)


def render(look: OtherLook, t: float, rays, R, rng, sensor: Sensor = SENSOR) -> tuple[np.ndarray, dict]:
    d_cam, inside = rays
    if d_cam.shape[:2] != (sensor.height, sensor.width):
        raise ValueError(
            f"rays of {d_cam.shape[1]} x {d_cam.shape[0]} px for a {sensor.width} x {sensor.height} sensor"
        )
    d_enu = d_cam @ R.T
    az, el = sun_truth(np.array([t]))
    s_enu = enu(az[0], el[0])
    s_cam = R.T @ s_enu
    zen = np.arccos(np.clip(d_enu[..., 2], -1, 1))
    chi = np.arccos(np.clip(d_enu @ s_enu, -1, 1))
    zs = math.radians(90 - el[0])
    sky_l = (
        0.06 * look.sky_level * cie_clear(zen, chi, zs, look.sky_type)
        if look.sky == "cie"
        else np.full(zen.shape, 0.12)
    )
    white = np.clip(
        0.35 * np.exp(-np.degrees(chi) / 12.0) + 0.4 * np.exp(-(90 - np.degrees(zen)) / 8.0), 0, 1
    )
    if look.sky != "cie":
        white[:] = 0.2
    rgb = sky_l[..., None] * ((1 - white)[..., None] * np.array([0.45, 0.68, 1.0]) + white[..., None])
    ground = d_enu[..., 2] < 0
    rgb[ground] = np.array([0.06, 0.05, 0.04])
    if look.sky == "dome":  # an integrating dome over the lens: the same light everywhere
        rgb[:] = 0.12
    # clouds: optical depth of each puff along each ray, drifting
    tau = np.zeros(zen.shape)
    tau_sun = 0.0
    for caz, cel, sx, sy, tmax, (vaz, vel) in look.clouds:
        m = (t % 86400) / 60.0
        c_dir = enu(caz + vaz * m, cel + vel * m)
        e_ax = np.cross([0, 0, 1.0], c_dir)
        e_ax /= np.linalg.norm(e_ax)
        n_ax = np.cross(c_dir, e_ax)
        x = np.degrees(np.arctan2(d_enu @ e_ax, d_enu @ c_dir))
        y = np.degrees(np.arctan2(d_enu @ n_ax, d_enu @ c_dir))
        tau += tmax * np.exp(-0.5 * ((x / sx) ** 2 + (y / sy) ** 2)) * (d_enu @ c_dir > 0)
        xs = math.degrees(math.atan2(s_enu @ e_ax, s_enu @ c_dir))
        ys = math.degrees(math.atan2(s_enu @ n_ax, s_enu @ c_dir))
        tau_sun += tmax * math.exp(-0.5 * ((xs / sx) ** 2 + (ys / sy) ** 2)) * (s_enu @ c_dir > 0)
    cloud_a = 1 - np.exp(-tau)
    # forward scattering near the sun: strongest through a cloud of optical depth ~1 (the
    # silver lining), washed out in a thick one (multiple scattering makes it diffuse)
    lit = 0.9 + 2.5 * np.exp(-np.degrees(chi) / 6.0) * np.minimum(tau * np.exp(1.0 - tau), 1.0)
    rgb = rgb * (1 - cloud_a[..., None]) + (cloud_a * 0.3 * lit)[..., None]
    # glare
    am = 1 / max(math.sin(math.radians(max(el[0], 0.5))), 0.05)
    trans = math.exp(-0.12 * (am - 1)) * math.exp(-tau_sun)
    su, sv = project(s_cam, sensor)
    u, v = np.meshgrid(np.arange(sensor.width, dtype=np.float64), np.arange(sensor.height, dtype=np.float64))
    dpx = np.hypot(u - su, v - sv)
    px_per_deg = sensor.f_eq * math.pi / 180.0

    def g_ang(c_deg):
        if look.aureole == "disk":  # a hard disk three times full scale, an exponential halo
            r = look.sat_radius_deg
            return np.where(c_deg <= r, 3.0, 0.7 * np.exp(-np.maximum(c_deg - r, 0.0) / 1.5))
        if look.aureole == "gauss":
            return np.exp(-((c_deg / 1.6) ** 2)) + 0.03 / (1 + (c_deg / 1.0) ** 2) ** 1.5
        return np.exp(-c_deg / 0.9) + 0.02 / (1 + (c_deg / 0.5) ** 2)

    def g_pix(d):
        return 1 / (1 + (d / (0.8 * px_per_deg)) ** 2)

    w = look.veil_weight
    gain = 1 / ((1 - w) * g_ang(look.sat_radius_deg) + w * g_pix(look.sat_radius_deg * px_per_deg))
    cloud_aureole = np.exp(-0.5 * tau)  # cloud in front of the aureole dims it
    glare = gain * trans * ((1 - w) * g_ang(np.degrees(chi)) * cloud_aureole + w * g_pix(dpx))
    if look.aureole == "disk":  # drawn as it is: the disk's size set by its radius alone
        glare = trans * g_ang(np.degrees(chi)) * cloud_aureole
    glare = np.where(el[0] > -0.5 and look.sun, glare, 0.0)
    lin = rgb + glare[..., None]
    if look.bloom > 0:
        sat = lin.min(axis=-1) >= 1.0
        cols = np.flatnonzero(sat.any(axis=0))
        if cols.size:
            r_sat = math.sqrt(sat.sum() / math.pi)
            excess = np.maximum(glare - 1, 0).sum(axis=0)
            for c in cols:
                top = int(np.argmax(sat[:, c]))
                length = int(look.bloom * r_sat * math.sqrt(excess[c] / excess.max()))
                lin[max(top - length, 0) : top, c, :] += 1.5
    r_img = np.hypot(u - sensor.cx, v - sensor.cy) / (2 * sensor.f_eq * math.sin(THETA_MAX / 2))
    lin = look.exposure * lin * (1 - look.vignetting * r_img**2)[..., None]
    lin[~inside] = 0.0
    e = np.minimum(lin, 4.0) * 10000.0
    if look.noise:
        e = e + rng.standard_normal(e.shape) * np.sqrt(np.maximum(e, 0) + 64.0)
    x = np.clip(e / 10000.0, 0, 1)
    out = tone_curve(x, look.tone) * 255
    if look.post_noise > 0:  # as a renderer that adds noise to its output would: the
        out = out + rng.standard_normal(out.shape) * look.post_noise  # plateau is noisy too
    img = np.ascontiguousarray(np.clip(np.rint(out), 0, 255).astype(np.uint8)[..., ::-1])
    if look.turned:  # counter-clockwise: its bloom runs along the rows (:func:`bundle` turns too)
        img = np.ascontiguousarray(np.rot90(img, 1))
    if look.jpeg and look.noise:
        img = cv2.imdecode(
            cv2.imencode(".jpg", img, [cv2.IMWRITE_JPEG_QUALITY, look.jpeg])[1], cv2.IMREAD_COLOR
        )
    # hidden: nothing of the sun saturates (its peak through the cloud is under full scale)
    peak = gain * trans * ((1 - w) * float(g_ang(0.0)) + w)
    vis = "visible" if tau_sun < 0.1 else ("hidden" if peak < 1.0 else "dimmed")
    return img, {"sun_enu": s_enu, "visibility": vis, "el_deg": float(el[0])}


def tone_curve(x: np.ndarray, tone: str) -> np.ndarray:
    """Linear exposure (0-1, clipped) to the output's 0-1."""
    if tone == "srgb":
        return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)
    if tone == "gamma2.2":
        return x ** (1 / 2.2)
    if tone == "filmic":  # highlights rolled off: flat at the top, as many cameras' JPEGs
        y = x ** (1 / 2.2)
        return 0.5 * y * y * (3 - 2 * y) + 0.5 * y
    return x


def vignetting_fit(vignetting: float) -> tuple[float, ...]:
    """The bundle's vignetting coefficients (``1 + c1 t^2 + c2 t^4 + c3 t^6``, t the field
    angle in rad) of the renderer's law ``1 - v (r / r_max)^2`` through the equisolid lens."""
    th = np.linspace(0.0, THETA_MAX, 400)
    v = 1.0 - vignetting * (np.sin(th / 2) / math.sin(THETA_MAX / 2)) ** 2
    A = np.stack([th**2, th**4, th**6], 1)
    c, *_ = np.linalg.lstsq(A, v - 1.0, rcond=None)
    return tuple(float(x) for x in c)


def radiometry(look: OtherLook):
    """The look's ``[radiometry]`` (``look.radiometry``): ``"exact"``, the camera's as its
    maker states it (the tone curve, named when it is a standard one, else its table) with
    a fit of its vignetting law, as the lens is handed over as a ``cv2.fisheye`` fit;
    ``"calibrated"``, measured by :func:`calibrated_radiometry` from the renderer's own
    brackets and flat fields; ``"none"``: not declared (None)."""
    from controller.calibration.fisheye_bundle import RadiometryCal

    if look.radiometry == "none":
        return None
    if look.radiometry == "calibrated":
        return calibrated_radiometry(look.tone, look.vignetting)
    vig = vignetting_fit(look.vignetting) if look.vignetting else ()
    if look.tone == "srgb":
        return RadiometryCal(response="srgb", vignetting=vig)
    if look.tone == "gamma2.2":
        return RadiometryCal(response="gamma", gamma=2.2, vignetting=vig)
    if look.tone == "linear":
        return RadiometryCal(response="linear", vignetting=vig)
    x = np.linspace(0.0, 1.0, 4097)
    table = np.interp(np.arange(256) / 255.0, tone_curve(x, look.tone), x)
    return RadiometryCal(response="table", table=tuple(float(v) for v in table), vignetting=vig)


def calibrated_radiometry(tone: str, vignetting: float):
    """The camera's ``[radiometry]`` as ``heliotrack calibrate fisheye response`` and
    ``vignetting`` measure it on this renderer's frames: 8 brackets 1 EV apart of the clear
    sky without the sun (Mar 20, 11 h UTC), then 3 flat fields of an integrating dome read
    through that response."""
    from controller.calibration.fisheye_bundle import RadiometryCal
    from controller.calibration.fisheye_radiometry import response_from_brackets, vignetting_from_flats
    from controller.vision.fisheye.lens import FisheyeLens
    from controller.vision.fisheye.radiometry import Radiometry

    rays, R = pixel_rays(), rotation()
    t = utc_midnight(2025, 3, 20) + 11 * 3600.0
    base = OtherLook("calibration", tone=tone, vignetting=vignetting, sun=False)
    rng = np.random.default_rng(5)
    exposures = [0.25 * 2.0**k for k in range(8)]
    brackets = [render(replace(base, exposure=e), t, rays, R, rng)[0] for e in exposures]
    response = RadiometryCal(
        response="table", table=tuple(float(v) for v in response_from_brackets(brackets, exposures))
    )
    flats = [render(replace(base, sky="dome", exposure=5.0), t, rays, R, rng)[0] for _ in range(3)]
    lens = FisheyeLens.from_camera(bundle(R).camera)
    vig = vignetting_from_flats(flats, lens, Radiometry.from_cal(response)).coeffs
    return replace(
        response,
        vignetting=tuple(float(c) for c in vig),
        method="brackets and flat fields of the second renderer",
    )


def bundle(R: np.ndarray, look: OtherLook | None = None, sensor: Sensor = SENSOR):
    """The pipeline's bundle: the KB fit of the lens, the true rotation, the site, and the
    look's camera radiometry (:func:`radiometry`) when given."""
    from controller.calibration.camera import CameraCal
    from controller.calibration.fisheye_bundle import FisheyeBundle, OrientationCal, SiteCal, as_mat3

    K, D = kb_fit(sensor)
    f, cx, cy, w, h = sensor.f_eq, sensor.cx, sensor.cy, sensor.width, sensor.height
    if look is not None and look.turned:  # the image's (u, v) is the sensor's (v, w - 1 - u)
        cx, cy, w, h, R = cy, w - 1 - cx, h, w, R @ np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1.0]])
    cam = CameraCal(
        width=w,
        height=h,
        fx=f,
        fy=f,
        cx=cx,
        cy=cy,
        dist=tuple(float(x) for x in D),
        model="fisheye",
    )
    return FisheyeBundle(
        camera=cam,
        orientation=OrientationCal(enu_from_camera=as_mat3(R)),
        site=SiteCal(latitude=SITE[0], longitude=SITE[1], altitude=SITE[2]),
        radiometry=None if look is None else radiometry(look),
    )


#: as a simple renderer draws the sky: a hard disk and a halo, linear output, no vignetting
#: (so the bundle needs no [radiometry])
SIMPLE = OtherLook(
    "other renderer, hard disk and halo, linear, no vignetting",
    aureole="disk",
    tone="linear",
    vignetting=0.0,
    radiometry="none",
)
CLEAR_LOOKS = (
    OtherLook("other renderer"),
    OtherLook(
        "other renderer, radiometry calibrated from its brackets and flat fields", radiometry="calibrated"
    ),
    OtherLook("other renderer, radiometry not declared", radiometry="none"),
    OtherLook("other renderer, glare all on the sensor", veil_weight=1.0),
    OtherLook("other renderer, glare all on the sky", veil_weight=0.0),
    OtherLook("other renderer, wide glare (5 deg)", sat_radius_deg=5.0),
    OtherLook("other renderer, upward bloom 2 radii", bloom=2.0),
    OtherLook("other renderer, linear output", tone="linear"),
    OtherLook("other renderer, gamma 2.2, Gaussian aureole", tone="gamma2.2", aureole="gauss"),
    OtherLook("other renderer, filmic tone, Gaussian aureole", tone="filmic", aureole="gauss"),
    OtherLook("other renderer, linear, noise after the clip (3 grey levels)", tone="linear", post_noise=3.0),
    OtherLook("other renderer, upward bloom 1 radius", bloom=1.0),
    OtherLook("other renderer, upward bloom 4 radii", bloom=4.0),
    # other sky shapes at type 12's circumsolar level (only the shape differs), then one as exposed
    *(
        OtherLook(f"other renderer, {n}, same circumsolar level", sky_type=k, sky_level=SAME_LEVEL[k])
        for k, n in SKIES
    ),
    OtherLook("other renderer, CIE sky type 15, circumsolar sky clipped", sky_type=15),
    SIMPLE,
    # a sensor read out across the stored image (the frame turned 90 deg): the bloom along the rows
    OtherLook("other renderer, upward bloom 2 radii, frame turned 90 deg", bloom=2.0, turned=True),
    OtherLook("other renderer, upward bloom 4 radii, frame turned 90 deg", bloom=4.0, turned=True),
)


def utc_midnight(y: int, m: int, d: int) -> float:
    from datetime import UTC, datetime

    return datetime(y, m, d, tzinfo=UTC).timestamp()


# at 1280 x 960: the look as described, the glare and the smear that differ most, the simple look
HD_LOOKS = (CLEAR_LOOKS[0], CLEAR_LOOKS[5], CLEAR_LOOKS[6], SIMPLE)


def clear(quick: bool, sensor: Sensor = SENSOR, looks: tuple[OtherLook, ...] = CLEAR_LOOKS) -> dict:
    """Clear days (Mar 20, Jun 21, Dec 21; every 30 min, 60 in quick runs; sun above 5 deg)."""
    from controller.vision.fisheye import FisheyeEstimator

    from .fisheye_suites import angle_deg, stats

    rays, R = pixel_rays(sensor), rotation()
    step = 3600 if quick else 1800
    out = {}
    for look in looks[:2] if quick else looks:
        est = FisheyeEstimator(bundle(R, look, sensor))
        rng = np.random.default_rng(17)
        errs, missing, n = [], {}, 0
        for day in ((2025, 3, 20), (2025, 6, 21), (2025, 12, 21)):
            est.reset_sequence()
            ts = utc_midnight(*day) + np.arange(0, 86400, step, dtype=float)
            _, els = sun_truth(ts)
            for t in ts[els >= 5.0]:
                img, truth = render(look, float(t), rays, R, rng, sensor)
                n += 1
                r = est.estimate_image(img, float(t))
                if r.found:
                    from controller.sun.types import azel_to_enu

                    errs.append(angle_deg(azel_to_enu(r.az_deg, r.el_deg), truth["sun_enu"]))
                else:
                    missing[r.reason] = missing.get(r.reason, 0) + 1
        out[look.name] = {"frames": n, "found": len(errs), "error": stats(errs), "not_found": missing}
    return out


def cloud_sequences(quick: bool, seed: int = 31) -> list:
    """Sequences of 30 frames a minute apart, 2-4 puffs drifting across the sun's region."""
    rng = np.random.default_rng(seed)
    out = []
    for k in range(3 if quick else 10):
        day = ((2025, 3, 20), (2025, 6, 21), (2025, 9, 22), (2025, 12, 21))[k % 4]
        ts = utc_midnight(*day) + np.arange(0, 86400, 600, dtype=float)
        azs, els = sun_truth(ts)
        ok = np.flatnonzero(els >= 15)
        i = int(rng.choice(ok[: max(len(ok) - 3, 1)]))
        t0, saz, sel = float(ts[i]), float(azs[i]), float(els[i])
        m0 = (t0 % 86400) / 60.0
        puffs = []
        for _ in range(int(rng.integers(2, 5))):
            vaz, vel = (float(x) for x in rng.uniform(-0.5, 0.5, 2))
            off = rng.uniform(-12, 12, 2)
            # placed so that it crosses near the sun during the sequence
            caz = saz + off[0] - vaz * (m0 + 15)
            cel = float(np.clip(sel + off[1] * 0.5 - vel * (m0 + 15), 5, 85))
            puffs.append(
                (
                    caz,
                    cel,
                    float(rng.uniform(3, 9)),
                    float(rng.uniform(2, 6)),
                    float(rng.uniform(2, 12)),
                    (vaz, vel),
                )
            )
        out.append(
            (OtherLook(f"clouds {k}", clouds=puffs), [t0 + 60.0 * j for j in range(10 if quick else 30)])
        )
    return out


def clouds(quick: bool) -> dict:
    """Correct detections, misses and false detections under the second renderer's clouds."""
    from controller.vision.fisheye import FisheyeEstimator

    from .fisheye_suites import Tally

    rays, R = pixel_rays(), rotation()
    tally = Tally()
    for look, ts in cloud_sequences(quick):
        est = FisheyeEstimator(bundle(R, look))
        rng = np.random.default_rng(int(ts[0]) & 0xFFFF)
        for t in ts:
            img, truth = render(look, t, rays, R, rng)
            tally.add(est.estimate_image(img, t), truth)
    return tally.summary()


def run(quick: bool = False) -> dict:
    return {
        "clear": clear(quick),
        "clear_1280x960": clear(quick, SENSOR.scaled(2.0), HD_LOOKS[:1] if quick else HD_LOOKS),
        "clouds": clouds(quick),
    }
