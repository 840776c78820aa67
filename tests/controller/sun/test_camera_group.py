"""A camera's own cadence, colour and prior; several cameras into one filter."""

import numpy as np

from controller.sun.camera import CallableFrameSource, CameraSunSensor
from controller.sun.cameras import CameraGroup
from controller.sun.types import SunObservation

T0 = 1_710_928_800.0


class Result:
    def __init__(self, obs):
        self.obs = obs
        self.reason = None if obs is not None else "no_sun_glare"

    def observation(self):
        return self.obs


class Recorder:
    """An estimator that notes what it was handed and finds the sun with ``sigma``."""

    def __init__(self, sigma: float, name: str, find: bool = True):
        self.sigma, self.name, self.find = sigma, name, find
        self.calls: list[tuple[tuple[int, ...], object]] = []

    def estimate_image(self, image, t, prior=None):
        self.calls.append((image.shape, prior))
        obs = SunObservation(t, 180.0, 50.0, self.sigma, sensor=self.name) if self.find else None
        return Result(obs)


def colour_frames(t: float) -> np.ndarray:
    img = np.full((48, 64, 3), 60, np.uint8)
    img[20:28, 30:38] = 255
    return img


def test_a_camera_looks_once_per_interval():
    est = Recorder(0.1, "hotspot")
    cam = CameraSunSensor(CallableFrameSource(colour_frames), est, "hotspot", interval_s=300.0)
    got = [len(cam.observations(T0 + k * 60.0)) for k in range(11)]
    assert got == [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1]
    assert est.calls[0][0] == (48, 64)  # grey by default


def test_colour_and_prior_reach_the_estimator():
    est = Recorder(0.02, "fisheye")
    seen: list[float] = []

    def prior(t: float):
        seen.append(t)
        return (180.0, 50.0, 0.1)

    cam = CameraSunSensor(CallableFrameSource(colour_frames), est, "fisheye", colour=True, prior=prior)
    cam.observations(T0)
    assert est.calls == [((48, 64, 3), (180.0, 50.0, 0.1))] and seen == [T0]


def test_a_group_returns_every_cameras_observation_with_its_own_sigma():
    hot = CameraSunSensor(CallableFrameSource(colour_frames), Recorder(0.1, "hotspot"), "hotspot")
    fish = CameraSunSensor(
        CallableFrameSource(colour_frames), Recorder(0.02, "fisheye", find=False), "fisheye", interval_s=120.0
    )
    group = CameraGroup([hot, fish])
    first = group.observations(T0)
    assert [(o.sensor, o.sigma_deg) for o in first] == [("hotspot", 0.1)]
    assert group.last_outcome == "fisheye: no_sun_glare"
    fish.estimator.find = True
    assert [o.sensor for o in group.observations(T0 + 60)] == ["hotspot"]  # fisheye not due
    both = group.observations(T0 + 120)
    assert [(o.sensor, o.sigma_deg) for o in both] == [("hotspot", 0.1), ("fisheye", 0.02)]
    assert group.outcomes == {"hotspot: found": 3, "fisheye: no_sun_glare": 1, "fisheye: found": 1}
    assert group.by_camera()["fisheye"] == {"no_sun_glare": 1, "found": 1}


class Faulty(Recorder):
    """An estimator with a bug that shows on some frames only."""

    def estimate_image(self, image, t, prior=None):
        if int(t) % 120 == 0:
            raise ValueError("Maximum allowed dimension exceeded")
        return super().estimate_image(image, t, prior)


def test_an_estimator_that_raises_costs_its_look_not_the_loop(caplog):
    cam = CameraSunSensor(CallableFrameSource(colour_frames), Faulty(0.1, "fisheye"), "fisheye")
    got = [len(cam.observations(T0 + k * 60.0)) for k in range(4)]
    assert got == [0, 1, 0, 1]  # T0 is a multiple of 120 s
    assert cam.outcomes == {"estimator_error: ValueError": 2, "found": 2}
    tracebacks = [r for r in caplog.records if r.exc_info is not None]
    assert len(tracebacks) == 1  # logged once, then counted
