"""Where between the rim's fix and the rings' a camera's sun lies (locator)."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pytest

from controller.vision.fisheye import locator
from controller.vision.fisheye.locator import AirmassWeight, LocatorChoice, blend_weight, weight_by_airmass
from controller.vision.fisheye.rings import SkyReading, ring_direction

from .helpers import E1, E2, RHO, A, angle_deg, product_sky


class _Lens:
    """A pinhole of focal 100 px at (320, 240), as :meth:`.lens.FisheyeLens.project` answers."""

    def project(self, d):
        return 320.0 + 100.0 * d[:, :2] / d[:, 2:], np.ones(len(d), bool)


class _Gate:
    """A gate around ``centre`` (ENU) of ``radius_deg``, as :class:`.gates.Gate` measures."""

    def __init__(self, name, centre, radius_deg, frame="enu"):
        self.name, self.centre, self.radius_deg, self.frame = name, centre, radius_deg, frame

    def distance_deg(self, v):
        return math.degrees(math.acos(min(1.0, float(v @ self.centre))))


@dataclass
class _Fit:
    """The parts of a :class:`.glare.GlareFit` that :meth:`LocatorChoice.place` reads."""

    sky_reading: SkyReading | None
    flags: list
    centre_uv: tuple = (320.0, 240.0)


@dataclass
class _Cand:
    """The parts of a :class:`.default.Candidate` that :meth:`LocatorChoice.place` reads."""

    fit: _Fit
    d_cam: np.ndarray
    d_enu: np.ndarray
    el_deg: float


def _enu(az_deg: float, el_deg: float) -> np.ndarray:
    az, el = math.radians(az_deg), math.radians(el_deg)
    return np.array([math.sin(az) * math.cos(el), math.cos(az) * math.cos(el), math.sin(el)])


def _frame(c: LocatorChoice, el: float, rim_dv: float, rings_dv: float, across: float = 0.0) -> None:
    """One frame at elevation ``el`` whose rim and rings read the sun ``rim_dv`` and
    ``rings_dv`` deg high (both ``across`` deg east of it)."""
    c.observe(el, _enu(180.0 - across, el + rim_dv), _enu(180.0 - across, el + rings_dv), _enu(180.0, el))


def test_the_weight_is_where_between_the_two_fixes_the_sun_lies():
    rim = np.array([[0.0, -0.001, 0.0]] * 5)  # 0.057 deg low
    assert blend_weight(rim, rim + [0.0, 0.005, 0.0]) == pytest.approx(0.2)  # rings 0.23 high
    assert blend_weight(rim, rim + [0.0, 0.001, 0.0]) == pytest.approx(1.0)  # rings on the sun
    assert blend_weight(rim, rim + [0.0, 0.0005, 0.0]) == 1.0  # beyond them: held at the rings
    assert blend_weight(rim * 0.0, rim + [0.0, 0.005, 0.0]) == 0.0  # the rim on the sun
    assert blend_weight(rim, rim * 0.0 + [0.0, -0.003, 0.0]) == 0.0  # rings further low: the rim
    # a cloud's frame, both fixes 1 deg off across the vertical, does not set the weight
    cloud = np.array([[0.0174, -0.001, 0.0]])
    assert blend_weight(np.vstack([rim, cloud]), np.vstack([rim + [0, 0.005, 0], cloud + [0, 0.01, 0]])) == (
        pytest.approx(0.2)
    )
    assert blend_weight(
        np.vstack([rim, cloud]), np.vstack([rim + [0, 0.005, 0], cloud + [0, 0.01, 0]]), trim_k=math.inf
    ) == pytest.approx(0.156, abs=1e-3)  # untrimmed it would


def test_the_weight_is_learned_from_the_frames_before_by_elevation_and_not_a_frames_own():
    c = LocatorChoice()
    assert c.weight(20.0) == locator.UNKNOWN_PRIOR == 0.5  # nothing learned, nor chosen: halfway
    _frame(c, 20.0, -0.05, 0.2)
    assert c.weight(20.0) == 0.5  # one frame is no evidence
    for el in (19.0, 20.5, 21.0):  # the rim 0.05 deg low at 20 deg, the rings 0.2 high
        _frame(c, el, -0.05, 0.2)
    assert c.weight(20.0) == pytest.approx(0.2, abs=1e-3)
    for el in (50.0, 51.0, 52.0, 53.0):  # at 50 deg the rings read the sun, the rim 0.1 low
        _frame(c, el, -0.1, 0.0)
    assert c.weight(51.0) == pytest.approx(1.0) and c.weight(20.0) == pytest.approx(0.2, abs=1e-3)
    assert 0.2 < c.weight() < 1.0  # one weight over all frames
    assert 0.2 < c.weight(35.0) < 1.0 and c.weight(35.0) != c.weight()  # no band: by the air mass
    _frame(c, 20.0, -1.5, 0.2)  # a fix beyond max_deg: the frame is not counted
    assert c.weight(20.0) == pytest.approx(0.2, abs=1e-3)
    assert c.rings == (c.weight() >= 0.5)
    single = LocatorChoice(min_frames=1)
    _frame(single, 20.0, -0.1, 0.0)
    assert single.weight(20.0) == 1.0 and single.rings


def test_a_low_sun_with_no_band_of_its_own_is_weighed_by_the_air_mass():
    """Frames every 30 min see a low sun two or three times a day: where its band holds too
    few frames, the weight is the trend in the air mass over all frames, not their mean (the
    rim pulled by the horizon's sky below 25 deg, the rings off above 40)."""
    c = LocatorChoice()
    for el in (15.0, 18.0, 21.0, 24.0):  # the rim 0.2 deg high, the rings on the sun
        _frame(c, el, 0.2, 0.0)
    for el in (40.0, 50.0, 60.0):  # the rim on the sun, the rings 0.1 deg high
        _frame(c, el, 0.0, 0.1)
    mean = c.weight()
    assert 0.5 < mean < 1.0 and c.weight(8.0) == mean  # 7 frames: one weight over them all
    _frame(c, 70.0, 0.0, 0.1)
    assert c.weight() < mean < c.weight(8.0) == 1.0  # 8 frames: by the air mass, 8 deg as 15-24
    trend = [c.weight(el) for el in (12.0, 19.0, 30.0, 50.0, 80.0)]  # a line in the air mass
    assert trend == sorted(trend, reverse=True) and trend[1] > 0.9 and trend[3] < 0.3
    el = np.array([10.0, 20.0, 30.0, 60.0])
    rim = np.array([[0.0, 0.0, 0.001]] * 4)
    w = weight_by_airmass(el, rim, rim * 0.0)  # the rings on the sun at every elevation
    assert w.w0 == pytest.approx(1.0) and w.w1 == pytest.approx(0.0, abs=1e-9)
    x = [1.0 / math.sin(math.radians(e)) - 1.0 for e in (60.0, 10.0)]
    assert (w.x_lo, w.x_hi) == pytest.approx(x)
    steep = AirmassWeight(0.0, 1.0, 0.2, 0.5)  # frames at 42-56 deg: their trend held to that span
    assert steep.at(56.4) == pytest.approx(0.2, abs=1e-3) and steep.at(5.0) == steep.at(40.0) == 0.5


def test_the_rings_are_read_less_once_they_weigh_nothing():
    c = LocatorChoice(window=8, settled=4)
    for _ in range(3):
        _frame(c, 30.0, 0.01, 0.05)  # the rim on the sun (0.01 high), the rings further
    assert not c.rim_settled  # three frames: too few
    _frame(c, 30.0, 0.01, 0.05)
    assert c.rim_settled and not c.rings
    for _ in range(30):
        _frame(c, 30.0, -0.05, 0.0)  # the rings on the sun now: they weigh again
    assert not c.rim_settled and c.rings


def test_a_choice_made_always_takes_the_rings_and_never_settles_on_the_rim():
    c = LocatorChoice(window=8, settled=4, always=True)  # the calibration's rings pass
    assert c.rings and c.weight(30.0) == 1.0  # before any frame
    for _ in range(8):
        _frame(c, 30.0, 0.01, 0.05)  # the rim far better: a learned weight would be 0
    assert c.rings and c.weight(30.0) == 1.0 and not c.rim_settled


def test_the_calibration_days_choice_holds_until_frames_have_weighed():
    c = LocatorChoice(window=4, prior="rings")  # a bundle's [orientation] locator = "rings"
    assert c.rings and c.weight(30.0) == 1.0  # from the first frame
    _frame(c, 30.0, 0.02, 0.10)
    assert c.weight(30.0) == 1.0  # one frame is no evidence
    _frame(c, 30.0, 0.02, 0.10)
    assert c.weight(30.0) == 0.0 and not c.rings  # two frames where the rim agreed better
    assert LocatorChoice(prior="rim").weight(30.0) == 0.0 and not LocatorChoice(prior="rim").rings
    assert LocatorChoice().weight(30.0) == 0.5 and not LocatorChoice().path_rings  # no choice made


def _rings_of_a_sun_off_the_axis():
    """A product sky's rings about ``A`` with the sun 0.1 deg off it along E1: the reading,
    the zenith, ENU from camera (the identity) and the sun."""
    vals, chi, phi, up, _ = product_sky((math.radians(0.1), 0.0))
    reading = SkyReading(
        vals, chi, phi, RHO, np.ones(phi.size, bool), np.ones(vals.shape, bool), A, E1, E2, 6000.0
    )
    sun = A + math.radians(0.1) * E1
    return reading, up, np.eye(3), sun / np.linalg.norm(sun)


def test_place_uses_the_rings_once_they_lead_and_only_within_the_gates():
    reading, up, R, sun = _rings_of_a_sun_off_the_axis()

    cand = _Cand(_Fit(reading, []), A, A, 90.0)
    c = LocatorChoice(prior="rim")  # the calibration day chose the rim
    gates = [_Gate("ephemeris", sun, 1.0)]
    assert c.place(cand, gates, R, up, _Lens()) is cand  # nothing learned before this frame: the rim
    assert c.place(cand, gates, R, up, _Lens()) is cand  # one frame learned: not yet evidence
    second = c.place(cand, gates, R, up, _Lens())
    assert "ring_locator" in second.fit.flags
    u, v = second.fit.centre_uv  # the fix's own centre in the image
    assert u == pytest.approx(320.0 + 100.0 * second.d_cam[0] / second.d_cam[2])
    assert v == pytest.approx(320.0 + 100.0 * second.d_cam[1] / second.d_cam[2])
    assert math.degrees(math.acos(min(1.0, float(second.d_enu @ sun)))) < 0.01
    tight = [*gates, _Gate("sequence", A, 0.05)]  # the rings' fix is 0.1 deg from the anchor
    assert c.place(cand, tight, R, up, _Lens()) is cand
    assert c.place(cand, [_Gate("prior", sun, 1.0)], R, up, _Lens()) is cand  # no site: never


def test_a_camera_whose_calibration_chose_nothing_starts_halfway_between_the_fixes():
    """A surveyed bundle (no ``locator``): until two frames have weighed, the fix lies halfway
    between the rim's and the rings', but 0.1 deg from the rim at most (the third renderer's
    second frame at 1280: 0.188 deg by the rim, 0.116 halfway; our bright sky's rings 0.4 deg
    off, where the rim read the sun)."""
    reading, up, R, rings_fix = _rings_of_a_sun_off_the_axis()  # the rings 0.1 deg off the rim
    cand, gates = _Cand(_Fit(reading, []), A, A, 90.0), [_Gate("ephemeris", rings_fix, 1.0)]
    first = LocatorChoice().place(cand, gates, R, up, _Lens())
    assert "ring_locator" in first.fit.flags
    assert angle_deg(first.d_enu, A) == pytest.approx(0.05, abs=2e-3)
    assert angle_deg(first.d_enu, rings_fix) == pytest.approx(0.05, abs=2e-3)
    # rings 0.28 deg off the rim move it 0.1 deg at most (locator.UNKNOWN_MAX_MOVE_DEG)
    vals, chi, phi, up_far, _ = product_sky((math.radians(0.28), 0.0))
    far = SkyReading(vals, chi, phi, RHO, np.ones(phi.size, bool), np.ones(vals.shape, bool), A, E1, E2, 6e3)
    far_fix = ring_direction(far, up_far)
    assert far_fix is not None and angle_deg(far_fix, A) == pytest.approx(0.28, abs=0.01)
    moved = LocatorChoice().place(
        _Cand(_Fit(far, []), A, A, 90.0), [_Gate("ephemeris", far_fix, 1.0)], R, up_far, _Lens()
    )
    assert angle_deg(moved.d_enu, A) == pytest.approx(locator.UNKNOWN_MAX_MOVE_DEG, abs=1e-3)
    for held in (LocatorChoice(prior="rings"), LocatorChoice(always=True)):  # a choice made, or
        # the calibration's rings pass: not held back
        fix = held.place(
            _Cand(_Fit(far, []), A, A, 90.0), [_Gate("ephemeris", far_fix, 1.0)], R, up_far, _Lens()
        )
        assert angle_deg(fix.d_enu, far_fix) < 0.005


def test_place_puts_the_sun_where_the_frames_before_weighed_it_between_the_fixes():
    """A camera whose sun lies midway between its rim's fix and its rings' (the rim 0.05 deg
    one way, the rings 0.05 the other, as a wide glare's): after two frames, midway."""
    reading, up, R, rings_fix = _rings_of_a_sun_off_the_axis()  # the rings 0.1 deg off the rim
    sun = A + rings_fix
    sun /= np.linalg.norm(sun)
    cand, gates = _Cand(_Fit(reading, []), A, A, 90.0), [_Gate("ephemeris", sun, 1.0)]
    c = LocatorChoice(prior="rim")
    assert c.place(cand, gates, R, up, _Lens()) is cand and c.place(cand, gates, R, up, _Lens()) is cand
    assert c.weight(90.0) == pytest.approx(0.5, abs=0.01)  # the rings fix their sun to 0.0013 deg
    mid = c.place(cand, gates, R, up, _Lens())
    assert "ring_locator" in mid.fit.flags and angle_deg(mid.d_enu, sun) < 2e-3
    assert angle_deg(A, sun) == pytest.approx(0.05, abs=1e-4)


def test_where_the_chosen_rings_place_no_sun_the_rim_is_moved_by_its_offset_from_them():
    """A camera that has chosen the rings, whose rim reads the sun 0.1 deg off where its
    rings read it right: on a frame whose rings place no sun (here no reading at all, as
    under a cloud that makes them rough) the rim's fix is moved by its median offset from
    the rings', once three frames within 2 deg of its elevation have given it, or else the
    three nearest within 8 deg."""
    reading, up, R, sun = _rings_of_a_sun_off_the_axis()
    gates = [_Gate("ephemeris", sun, 1.0)]
    seen, blind = _Cand(_Fit(reading, []), A, A, 90.0), _Cand(_Fit(None, []), A, A, 90.0)
    c = LocatorChoice(prior="rings")  # the calibration day chose the rings
    for _ in range(3):
        assert c.place(blind, gates, R, up, _Lens()) is blind  # no offsets yet (then 1, then 2)
        assert "ring_locator" in c.place(seen, gates, R, up, _Lens()).fit.flags
    moved = c.place(blind, gates, R, up, _Lens())
    assert "rim_by_rings" in moved.fit.flags and angle_deg(A, sun) == pytest.approx(0.1, abs=1e-6)
    assert angle_deg(moved.d_enu, sun) < 0.01 and moved.d_cam is not A
    u, v = moved.fit.centre_uv
    assert u == pytest.approx(320.0 + 100.0 * moved.d_cam[0] / moved.d_cam[2])
    low = _Cand(_Fit(None, []), A, A, 83.0)  # 7 deg from the offsets': the three nearest apply
    assert "rim_by_rings" in c.place(low, gates, R, up, _Lens()).fit.flags
    lower = _Cand(_Fit(None, []), A, A, 81.0)  # 9 deg from them: none applies
    assert c.place(lower, gates, R, up, _Lens()) is lower
    assert c.place(blind, [*gates, _Gate("sequence", A, 0.05)], R, up, _Lens()) is blind  # beyond a gate
    rim = LocatorChoice(prior="rim")  # a camera whose choice is the rim keeps its rim's fix
    for _ in range(3):
        rim.place(seen, [_Gate("ephemeris", A, 1.0)], R, up, _Lens())  # the rim on the sun here
    assert not rim.rings and rim.place(blind, gates, R, up, _Lens()) is blind


def _rings_at(off_deg: float):
    """A product sky's rings about ``A`` with the sun ``off_deg`` deg off it along E1."""
    vals, chi, phi, up, _ = product_sky((math.radians(off_deg), 0.0))
    reading = SkyReading(
        vals, chi, phi, RHO, np.ones(phi.size, bool), np.ones(vals.shape, bool), A, E1, E2, 6e3
    )
    return reading, up


def test_rings_astray_from_the_cameras_learned_offset_are_treated_as_placing_no_sun():
    """A camera whose rings read the sun 0.3 deg off its rim along E1, frame after frame (the
    fourth renderer's low suns: the rim 0.45-0.7 deg below the rings at 17-22 deg).  A frame
    whose rings put it 0.3 deg the other way, 0.6 from that offset (its 17.7-deg sun at 1280
    x 960: the rings 0.93 deg low, read 0.65 off), has rings astray: the rim is moved by the
    learned offset instead; one whose rings lie 0.4 deg from it keeps them."""
    sun = A + math.radians(0.3) * E1
    sun /= np.linalg.norm(sun)
    gates, R = [_Gate("ephemeris", sun, 1.0)], np.eye(3)
    c = LocatorChoice(prior="rings")
    usual, up = _rings_at(0.3)
    for _ in range(3):
        assert "ring_locator" in c.place(_Cand(_Fit(usual, []), A, A, 90.0), gates, R, up, _Lens()).fit.flags
    assert c.weight(90.0) == pytest.approx(1.0, abs=0.01)
    astray, up = _rings_at(-0.3)
    placed = c.place(_Cand(_Fit(astray, []), A, A, 90.0), gates, R, up, _Lens())
    assert "rim_by_rings" in placed.fit.flags and angle_deg(placed.d_enu, sun) < 0.01
    near, up = _rings_at(-0.1)  # 0.4 deg from the learned offset: the rings, 0.4 deg off the sun
    placed = c.place(_Cand(_Fit(near, []), A, A, 90.0), gates, R, up, _Lens())
    assert "ring_locator" in placed.fit.flags and angle_deg(placed.d_enu, sun) == pytest.approx(0.4, abs=0.01)


def _day_of_sights(bias_deg, step_s: float = 1200.0):
    """A clear 20 Mar at 40 N: the sun every ``step_s`` while 5 deg up or more, (t, its ENU
    direction, the same moved ``bias_deg(el)`` deg towards the horizon)."""
    from controller.sun.source import Site
    from controller.vision.fisheye.gates import Ephemeris

    eph = Ephemeris(Site(latitude=40.0, longitude=-3.0, altitude=0.0))
    t0 = 1773964800.0  # 2026-03-20 00:00 UTC
    out = []
    for t in np.arange(t0, t0 + 86400.0, step_s):
        s = eph.direction(float(t))
        el = math.degrees(math.asin(s[2]))
        if el < 5.0:
            continue
        down = np.array([0.0, 0.0, -1.0]) - s * (-s[2])
        down /= np.linalg.norm(down)
        d = s + math.radians(bias_deg(el)) * down
        out.append((float(t), s, d / np.linalg.norm(d), el))
    return out


def _sky_bias(el: float) -> float:
    """A rim's sky-model error: 0.2 deg low at 20 deg, fading above and below (deg)."""
    return 0.2 * math.exp(-(((el - 20.0) / 8.0) ** 2))


def test_without_the_site_the_suns_own_path_chooses_the_locator_whose_sights_it_fits():
    """The rim reads the sun 0.2 deg low around 20 deg (a sky model's error, which comes and
    goes with the elevation) and the rings read it right: no site takes up the rim's error,
    so the rings are chosen once 6 sights above 12 deg span an hour, and not before; and
    the other way round when the rings are the ones in error."""

    def first_choice(sights) -> tuple[int | None, LocatorChoice]:
        c = LocatorChoice()
        decided = None
        for k, (t, s, biased, _) in enumerate(sights):
            assert not c.path_rings or decided is not None
            c.observe_path(t, biased, s)  # the rim's fix, the rings'
            if c.path_rings and decided is None:
                decided = k
        return decided, c

    sights = _day_of_sights(_sky_bias)
    decided, c = first_choice(sights)
    above = [k for k, (_, _, _, el) in enumerate(sights) if el >= 12.0]
    assert decided == above[5]  # the sixth sight above 12 deg (20-min frames: 1 h 40 min)
    dense = _day_of_sights(_sky_bias, step_s=120.0)
    decided_dense, _ = first_choice(dense)
    above = [k for k, (_, _, _, el) in enumerate(dense) if el >= 12.0]
    assert decided_dense == above[30]  # a sight every 2 min: the hour's span binds
    rim, rings = c._path_sq
    assert rings < 1e-5 < 0.001 < rim  # deg^2 about each fitted site (the rings: SPA against the fit's sun)
    other = LocatorChoice()
    for t, s, biased, _ in sights:
        other.observe_path(t, s, biased)  # the rim right, the rings 0.2 deg low
    assert not other.path_rings
    low = LocatorChoice()
    for t, s, biased, el in sights:
        if el < 12.0:
            low.observe_path(t, biased, s)
    assert low._path_sq is None  # under 12 deg the rim is cut by the horizon: no sight counts


def _two_sites_day(t0: float, rim_lat: float = 40.2, noise_deg: float = 0.03, rim_scale: float = 1.0):
    """A clear day from ``t0`` at 40 N, a sight every 20 min while 12 deg up or more: (t, the
    rim's fix: the sun of a site at ``rim_lat``, the rings' fix: the sun), both moved by the
    same ``noise_deg`` scatter (the rim's times ``rim_scale``), so that each fits its own
    site equally well (or the rim ``rim_scale`` times worse)."""
    from controller.sun.source import Site
    from controller.vision.fisheye.gates import Ephemeris

    sun = Ephemeris(Site(latitude=40.0, longitude=-3.0, altitude=0.0))
    shifted = Ephemeris(Site(latitude=rim_lat, longitude=-3.0, altitude=0.0))
    rng = np.random.default_rng(7)
    out = []
    for t in np.arange(t0, t0 + 86400.0, 1200.0):
        s = sun.direction(float(t))
        if s[2] < math.sin(math.radians(12.5)):
            continue
        kick = rng.standard_normal(3) * math.radians(noise_deg)
        moved = [
            d + k * kick - k * (kick @ d) * d for d, k in ((shifted.direction(float(t)), rim_scale), (s, 1.0))
        ]
        out.append((float(t), *(m / np.linalg.norm(m) for m in moved)))
    return out


def test_without_the_site_a_path_that_fits_both_locators_alike_leaves_the_choice_open():
    """Where a sky model's error has the shape of a change of latitude, the rim's sights fit a
    site as well as the rings' fit theirs: no choice is made, the camera stays halfway with
    its move bounded as before any comparison, and a choice made on an earlier day that told
    them apart is kept."""
    t0 = 1773964800.0  # 2026-03-20 00:00 UTC
    open_ = LocatorChoice()
    for t, rim, rings in _two_sites_day(t0):
        open_.observe_path(t, rim, rings)
    rim_sq, rings_sq = open_._path_sq
    assert 0.5 < rings_sq / rim_sq < 2.0  # compared, and alike
    assert open_.path_weight() == locator.UNKNOWN_PRIOR and not open_._learned(False)
    told = LocatorChoice()
    for t, s, biased, _ in _day_of_sights(_sky_bias):
        told.observe_path(t, biased, s)  # the rings right: chosen
    assert told.path_weight() == 1.0
    for t, rim, rings in _two_sites_day(t0 + 3 * 86400.0):  # past the sights kept (48 h)
        told.observe_path(t, rim, rings)
    rim_sq, rings_sq = told._path_sq
    assert 0.5 < rings_sq / rim_sq < 2.0 and told.path_weight() == 1.0
    rim_right = LocatorChoice()
    for t, s, biased, _ in _day_of_sights(_sky_bias):
        rim_right.observe_path(t, s, biased)  # the rim right, the rings 0.2 deg low
    assert rim_right.path_weight() == 0.0 and rim_right._learned(False)


def test_without_the_site_sights_of_a_high_sun_alone_are_not_compared():
    """A sky model's error grows with the air mass: sights all above 30 deg (a batch's second
    half read first, from noon down) are not compared, however many; from the first at or
    under 30 deg they are, and while no comparison has chosen, at every sight."""
    c = LocatorChoice()
    compared = []
    noon = 1773964800.0 + 12.3 * 3600.0  # 20 Mar at 40 N, 3 W: the sun 50 deg up
    for t, rim, rings in _two_sites_day(noon):
        if t > noon + 12 * 3600.0:
            break  # the afternoon only
        before = c._path_sq
        c.observe_path(t, rim, rings)
        compared.append((math.degrees(math.asin(rings[2])), c._path_sq is not before))
    assert not any(done for el, done in compared if el > 30.0)
    low = [done for el, done in compared if el <= 30.0]
    assert len(low) >= 5 and all(low) and c.path_weight() == locator.UNKNOWN_PRIOR  # alike: none chosen


def test_a_choice_from_few_sights_must_be_clearer():
    """The share under which one locator's squared RMS chooses the other's grows with the
    sights it rests on (1 % significance for ``2 n - 2`` degrees of freedom each), up to
    ``LEAD``: six sights need a ratio of 0.21, twenty-six the 0.5 of before."""
    assert locator.path_lead(6) == pytest.approx(0.206, abs=0.001)
    assert locator.path_lead(11) == pytest.approx(0.340, abs=0.001)
    assert locator.path_lead(26) > locator.LEAD
    assert [locator.path_lead(n) for n in (6, 11, 16, 21)] == sorted(
        locator.path_lead(n) for n in (6, 11, 16, 21)
    )
    c = LocatorChoice()
    for t, rim, rings in _two_sites_day(1773964800.0, rim_scale=1.8):  # the rim scattered 1.8 times as far
        c.observe_path(t, rim, rings)
        if c._path_sq is not None:
            break
    rim_sq, rings_sq = c._path_sq
    assert locator.path_lead(len(c._path)) < rings_sq / rim_sq < locator.LEAD  # under 0.5, not clear enough
    assert len(c._path) == 6 and c.path_weight() == locator.UNKNOWN_PRIOR
