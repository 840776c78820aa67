"""Several camera sun sensors feeding one sun-path filter (``control.sun_source = "fused"``).

Each camera keeps its own cadence (``interval_s``), estimator and uncertainty; the group
only collects what every camera measured at a look, so the filter weighs each observation
by its own sigma (the hotspot camera's ~0.1 deg and the fisheye's ~0.01-0.2 deg differ by
an order of magnitude).  It has the one-camera interface the loop and the reports use
(:meth:`observations`, ``outcomes``, ``last_outcome``, :meth:`close`).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence

from .camera import CameraSunSensor
from .types import SunObservation


class CameraGroup:
    """Cameras looked through one after the other at each look.

    Parameters
    ----------
    sensors : sequence of CameraSunSensor
        Each with a distinct ``name`` (``"hotspot"``, ``"fisheye"``).
    """

    name = "fused"

    def __init__(self, sensors: Sequence[CameraSunSensor]):
        self.sensors = list(sensors)
        self.last_outcome = ""

    def observations(self, t: float) -> list[SunObservation]:
        """Every camera's observation at ``t`` that was due and found, in the sensors' order
        (all stamped with their own frame times)."""
        out: list[SunObservation] = []
        for s in self.sensors:
            before = sum(s.outcomes.values())
            out += s.observations(t)
            if sum(s.outcomes.values()) != before:
                self.last_outcome = f"{s.name}: {s.last_outcome}"
        return out

    @property
    def outcomes(self) -> Counter[str]:
        """What each look of each camera gave, keyed ``"<camera>: <outcome>"``."""
        total: Counter[str] = Counter()
        for s in self.sensors:
            total.update({f"{s.name}: {k}": v for k, v in s.outcomes.items()})
        return total

    def by_camera(self) -> dict[str, dict[str, int]]:
        """The outcomes of each camera, by camera name."""
        return {s.name: dict(s.outcomes) for s in self.sensors}

    def close(self) -> None:
        for s in self.sensors:
            s.close()
