"""A fourth sky renderer for the fisheye sun sensor: the world (lens, pose, sky, clouds).

Written by a helper from a brief alone, without seeing ``hil/skycam``, the other renderers
or the pipeline, and ported here with its physics and numbers unchanged, except that the
sun's radiance and the sensor's blooming are a look's settings (:class:`Look`), so that the
bench can read the brief's compressed sun beside a physical one.  The scene is
:mod:`benchmarks.fisheye_fourth_scene`, the bench :mod:`benchmarks.fisheye_fourth`.  Where it
differs from the other three: a lens ``r = f (k sin(theta / k) + ...)`` between equidistant
and equisolid, 185 deg; a CIE type 12 sky plus a single-scattering aerosol aureole
(Henyey-Greenstein) that grows with the air mass; a veiling glare of two exponentials in
image pixels; a sensor that blooms both ways along its columns (an anti-blooming drain
keeps the spikes short) with a frame-transfer smear; an fBm cloud layer that glows by
forward scattering next to the sun; Cape Town.

The helper's notes:
fourth.py -- independent test-image renderer for a fisheye sky-camera sun detector.

Written from the brief alone (no pipeline code consulted).  Everything below is a
choice of this module; all radiances are linear RGB in a relative unit "S"
(roughly: clear-sky zenith radiance at a sun elevation of ~60 deg = 1 S).

Conventions
-----------
* Images: uint8 (H, W, 3), BGR.  Pixel (u, v) = (column, row) of pixel centre.
* Camera frame OpenCV (x right, y down, z optical axis).  M = enu_from_camera,
  d_enu = M @ d_cam.  Angles in degrees, azimuth clockwise from north.
* Sun truth: pvlib NREL SPA (method "nrel_numpy"), azimuth + apparent_elevation.

Lens
----
r(theta) = f * (k*sin(theta/k) + eps * theta^3 * exp(-theta^2)),  k = 1.45,
eps = 0.02 (a small odd "bump" term), 185 deg field (theta_max = 92.5 deg).
f chosen so that r(92.5 deg) = 0.48*H (230.4 px at 640x480, f ~ 176 px/rad).
Principal point: ((W-1)/2 + 5.3 s, (H-1)/2 - 3.8 s), s = W/640.  Square pixels.
Outside the image circle: no light (read noise only).  The pipeline-facing lens
is a cv2.fisheye (Kannala-Brandt) model fitted by scipy least_squares over
theta in [0, 92] deg (residual reported by `kb_fit`).  Rays are projected with
the true lens (inverse by a dense monotone LUT), never with cv2.fisheye.

Pose
----
M_level: z = Up, image-up (-y) -> azimuth 203 deg (horizontal), x = y cross z.
M = R_tilt @ M_level, R_tilt = rotation by 1.5 deg about n = Up x a, with a the
horizontal unit vector to azimuth 250 deg (so the optical axis tips 1.5 deg
towards azimuth 250).

Clear sky
---------
* CIE general sky type 12 (a=-1, b=-0.32, c=10, d=-3, e=0.45) for the
  gradation * indicatrix, L/Lz.  Zenith radiance Lz(gs) = ((sin gs + 0.08) /
  (sin 60 + 0.08))^0.7 S.
* Colour: base blue (R,G,B) = (0.50, 0.80, 1.70) (mean 1); whitened towards
  the horizon (w_h = 0.75 exp(-el/7 deg)) and the sun (w_s = 0.6 exp(-chi/12 deg)),
  w = 1-(1-w_h)(1-w_s).
* Aerosol aureole, single scattering of a plane-parallel aerosol layer seen from
  below, Henyey-Greenstein g = 0.80, single-scattering albedo 0.92,
  tau_a(550 nm) = 0.08 with Angstrom alpha = 1.3 (R/G/B at 610/540/465 nm):
  L = F0 w P(chi)/(4 pi) mu_s/(mu_s-mu_v) [exp(-tau/mu_s) - exp(-tau/mu_v)]
  (limit tau/mu exp(-tau/mu) for mu_v = mu_s): grows with air mass while
  tau*m < 1.  F0 = 20 S sr is the *physical* solar irradiance normal to the beam
  (TOA), attenuated by Rayleigh (0.063/0.101/0.190) + aerosol extinction with
  Kasten-Young air mass for the sun's colour.
* Horizon haze band: Gaussian in elevation, centre +0.3 deg, sigma 0.6 deg
  (FWHM 1.4 deg), amplitude 0.9 x local horizon sky, near-white.
* Ground (el < 0): albedo 0.15, grey-brown (1.16, 1.01, 0.83), Lambertian, lit
  by E_h = F0 T_atm T_cloud sin(el_sun) + pi * 1.6 Lz; static multiplicative
  texture (smooth +-12 %, fine +-5 %).  Blend ground/sky over +-0.1 deg.

Sun and optical glare
---------------------
* Disk 0.533 deg across, linear limb darkening I(mu)/I(1) = 1 - u (1 - mu),
  u = 0.62 (normalised to unit mean over the disk).  The disk radiance is deliberately
  compressed w.r.t. reality: TOA disk mean radiance L_disk = 9000 S (true sun
  would be ~F0/Omega_sun = 2.9e5 S), so that the disk saturates by a factor of a
  few hundred (dark looks ~4e2-8e2, normal looks ~1e3-2e3, mid/high sun).  It is
  extinguished by the atmosphere (colour) and by cloud transmittance T.
* Disk rendered by 9x9 super-sampling per pixel in a local patch, convolved with
  a Gaussian core sigma = 0.8 s px.
* Veiling glare wing (round on the sensor, not on the sky):
  L_wing(d) = L_disk_on_sensor * (a1 exp(-d/s1) + a2 exp(-d/s2)), d = image
  distance in px from the sun's image point, s1 = 6 s px, s2 = 25 s px,
  a1 = 1.2e-2, a2 = 1.2e-3 (saturated glare ~2-4 deg radius).  Scaled by T.

Sensor
------
Electrons = radiance * X, X chosen per frame (auto-exposure metered on the
*clear-sky* zenith radiance plus the veiling-glare wing there) so that the mean over B,G,R of the output grey level of
the clear zenith equals the look's `zenith_grey` (for the srgb look: after the
tone curve).  Full well 12000 e-, Poisson photon noise, read noise 5 e-,
10-bit ADC (FW -> 1023) then >> 2 to 8 bit (linear looks) or sRGB curve on the
10-bit value (srgb look).  Blooming: per channel and column, each run of
over-full pixels is clipped to FW and a fraction beta = 0.012 of its excess
charge (the rest is drained by the anti-blooming gate) spills half up, half
down, filling neighbours to FW -> spike length proportional to the excess.
Frame-transfer smear: every pixel in a column gains 2e-4 x that column's total
(raw) over-exposed charge.

Clouds
------
One layer at base_km; tau(x, y) from periodic spectral fBm (48 km tile, 512^2,
P(k) ~ (k^2 + k0^2)^(-3.3/2), k0 = 1/8 km^-1), threshold at the (1-cover)
quantile (+ a short 0 -> 0.3 ramp below), tau = 0.3 (40/0.3)^(s^0.8) inside,
s = normalised excess over the threshold (0 at edges, 1 at the 99.9 % point).
Frozen turbulence advected by the wind (wind_dir_deg = direction the wind blows
FROM, meteorological).  Line of sight crosses the layer at h tan(Z) (flat
earth); slant tau_v = tau / max(cos Z, 0.05).  Cloud radiance:
(a) diffuse: L_ref (1 - exp(-tau_v)) / (1 + 0.75 (1 - 0.85) tau), L_ref =
    (F0 T_atm mu_s + 1.6 pi Lz)/pi, neutral slightly bluish grey-white;
(b) forward scattered sun: F0 T_atm P_HG(chi; g=0.85)/(4 pi)
    (1 - exp(-tau_v)) exp(-(tau_v + tau/mu_s)/2).
Sky behind: * exp(-tau_v).  Far clouds fade into the sky with exp(-dist/60 km); beyond 10 km slant
distance tau is blended (to 30 km) into a blurred (sigma 4 cells) copy against aliasing.
Sun beam: T = exp(-tau(sun point)/cos Zs) (cos clamped >= 0.05), scales disk +
glare + ghost.  Truth visibility: hidden if el < 3 or T < 0.05, visible if
T >= 0.9, else dimmed.

Distractors (optional)
----------------------
(a) specular reflection at az 128 deg, el 3 deg, ellipse 0.5 x 0.7 deg
    (az x el), peak 40 FW, all frames; (b) aircraft glint: every 1200 s a
    plane crosses for 300 s at 0.5 deg/s along a seeded great circle, 2.5 s px
    disk, 8 FW; (c) lens ghost: disk 2 deg across at 2 c - p_sun, tint
    (B,G,R) = (0.55, 1.0, 0.5), peak 0.75 FW * T (green), soft edge.
"""

from __future__ import annotations

import datetime as _dt
import math
from dataclasses import dataclass

import numpy as np
import pvlib
from scipy.optimize import least_squares

# ----------------------------------------------------------------------------
# constants
LENS_K = 1.45
LENS_EPS = 0.02
THETA_MAX = math.radians(92.5)
PP_OFF = (5.3, -3.8)
TILT_DEG = 1.5
TILT_AZ = 250.0
HEADING = 203.0

CIE = dict(a=-1.0, b=-0.32, c=10.0, d=-3.0, e=0.45)  # type 12
SKY_BLUE = np.array([0.50, 0.80, 1.70])  # R, G, B
F0 = 20.0  # physical solar irradiance (S sr)
L_DISK = 9000.0  # compressed disk radiance (S)
SUN_RAD = math.radians(0.533 / 2)
LIMB_U = 0.62
TAU_R = np.array([0.063, 0.101, 0.190])  # Rayleigh R,G,B
TAU_A = 0.08 * (np.array([610.0, 540.0, 465.0]) / 550.0) ** -1.3
AER_G, AER_W = 0.80, 0.92
GROUND_ALB = 0.15
GROUND_COL = np.array([1.16, 1.01, 0.83])
GLARE_A1, GLARE_A2, GLARE_S1, GLARE_S2 = 1.2e-2, 1.2e-3, 6.0, 25.0
CORE_SIGMA = 0.8
FW = 12000.0
READ_E = 5.0
BLOOM_BETA = 0.012
SMEAR = 2e-4
CLOUD_G = 0.85


@dataclass(frozen=True)
class Look:
    name: str
    width: int
    height: int
    zenith_grey: float
    tone: str = "linear"  # or "srgb"
    jpeg_quality: int | None = None
    sun_radiance: float = 9000.0  # the disk's mean radiance, S (the brief's compressed sun; ~2.9e5 physical)
    bloom: float = 0.012  # share of a saturated run's excess charge that spills along its column


@dataclass(frozen=True)
class CloudSpec:
    cover: float
    wind_mps: float = 8.0
    wind_dir_deg: float = 250.0
    base_km: float = 2.0
    seed: int = 0


# ----------------------------------------------------------------------------
# lens
def lens_r_unit(theta):
    """r / f for the true lens."""
    theta = np.asarray(theta, dtype=float)
    return LENS_K * np.sin(theta / LENS_K) + LENS_EPS * theta**3 * np.exp(-(theta**2))


def kb_fit(f: float):
    """Least-squares Kannala-Brandt fit (f_kb, D, max residual px) to the true lens."""
    th = np.linspace(0.0, math.radians(92.0), 2000)
    r = f * lens_r_unit(th)
    A = np.stack([th, th**3, th**5, th**7, th**9], 1)
    c0 = np.linalg.lstsq(A, r, rcond=None)[0]
    p0 = np.r_[c0[0], c0[1:] / c0[0]]

    def res(p):
        fk, k1, k2, k3, k4 = p
        t2 = th * th
        return fk * th * (1 + t2 * (k1 + t2 * (k2 + t2 * (k3 + t2 * k4)))) - r

    sol = least_squares(res, p0, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    return float(sol.x[0]), [float(v) for v in sol.x[1:]], float(np.max(np.abs(res(sol.x))))


def srgb_encode(x):
    x = np.clip(x, 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1 / 2.4) - 0.055)


def enu_of(az_deg, el_deg):
    az, el = np.radians(az_deg), np.radians(el_deg)
    return np.stack([np.cos(el) * np.sin(az), np.cos(el) * np.cos(az), np.sin(el)], -1)


def rotation_about(axis, ang):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    K = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + math.sin(ang) * K + (1 - math.cos(ang)) * K @ K


def build_pose():
    h = math.radians(HEADING)
    y = -np.array([math.sin(h), math.cos(h), 0.0])
    z = np.array([0.0, 0.0, 1.0])
    x = np.cross(y, z)
    M0 = np.stack([x, y, z], 1)
    a = np.array([math.sin(math.radians(TILT_AZ)), math.cos(math.radians(TILT_AZ)), 0.0])
    R = rotation_about(np.cross(z, a), math.radians(TILT_DEG))
    return R @ M0


def sun_position(t_posix, site):
    times = [_dt.datetime.fromtimestamp(float(t), tz=_dt.UTC) for t in np.atleast_1d(t_posix)]
    sp = pvlib.solarposition.get_solarposition(times, site[0], site[1], altitude=site[2], method="nrel_numpy")
    return sp["azimuth"].to_numpy(float), sp["apparent_elevation"].to_numpy(float)


def airmass(el_deg):
    el = np.maximum(np.asarray(el_deg, float), -1.0)
    return 1.0 / (
        np.sin(np.radians(np.maximum(el, 0.0))) + 0.50572 * (np.maximum(el, 0.0) + 6.07995) ** -1.6364
    )


def hg(cosx, g):
    return (1 - g * g) / np.power(1 + g * g - 2 * g * cosx, 1.5)


def fbm_field(n, tile_km, beta, k0, rng):
    k = np.fft.fftfreq(n, d=tile_km / n)
    kk = np.sqrt(k[:, None] ** 2 + k[None, :] ** 2)
    amp = (kk**2 + k0**2) ** (-beta / 4)
    amp[0, 0] = 0
    z = rng.standard_normal((n, n)) + 1j * rng.standard_normal((n, n))
    f = np.real(np.fft.ifft2(z * amp))
    return (f - f.mean()) / f.std()


# ----------------------------------------------------------------------------
# ----------------------------------------------------------------------------
def clear_times(day: str, step_min: float = 20.0, site=(-33.92, 18.42, 20.0)) -> list[float]:
    d0 = _dt.datetime.fromisoformat(day).replace(tzinfo=_dt.UTC)
    t0 = d0.timestamp()
    ts = t0 + np.arange(0, 86400, step_min * 60.0)
    _, el = sun_position(ts, site)
    return [float(t) for t, e in zip(ts, el) if e >= 5.0]


def cloud_sequences() -> list[dict]:
    return [
        {
            "name": "summer_morning_c20",
            "start_utc": "2024-01-15T06:30:00+00:00",
            "minutes": 90,
            "step_s": 30,
            "clouds": CloudSpec(0.2, 7.0, 200.0, 1.5, 11),
            "distractors": False,
        },
        {
            "name": "winter_noon_c40",
            "start_utc": "2024-06-20T09:30:00+00:00",
            "minutes": 120,
            "step_s": 30,
            "clouds": CloudSpec(0.4, 10.0, 310.0, 2.0, 22),
            "distractors": False,
        },
        {
            "name": "autumn_afternoon_c60",
            "start_utc": "2024-04-10T12:30:00+00:00",
            "minutes": 90,
            "step_s": 30,
            "clouds": CloudSpec(0.6, 6.0, 250.0, 2.5, 33),
            "distractors": False,
        },
        {
            "name": "spring_morning_c15_distractors",
            "start_utc": "2024-09-25T07:00:00+00:00",
            "minutes": 60,
            "step_s": 30,
            "clouds": CloudSpec(0.15, 8.0, 160.0, 1.8, 44),
            "distractors": True,
        },
        {
            "name": "summer_evening_c40",
            "start_utc": "2024-12-05T15:00:00+00:00",
            "minutes": 90,
            "step_s": 30,
            "clouds": CloudSpec(0.4, 9.0, 135.0, 3.0, 55),
            "distractors": False,
        },
    ]
