"""One drive axis of a row that carries its own sky camera: error in, setpoint out.

Two modes:

* ``paper``: the paper's use.  Only the camera: each frame's error goes through the fuzzy
  PID and the setpoint moves by its output; with no sun (cloud, night) the setpoint holds.
* ``assisted`` (default): ``setpoint = reference + offset + correction``.  ``reference`` is
  the open-loop angle (ephemeris and row geometry), ``offset`` the row's learned
  misalignment (:class:`~.learner.OffsetLearner`), ``correction`` the fuzzy PID's output on
  the camera's residual error.  When the learner's estimate moves, the correction moves
  the other way by the same amount (bumpless), so the correction tends to zero as the
  offset is learned.  Without the sun, the correction decays and the learned offset keeps
  the row on the sun through the gap.

Angles in degrees; ``error`` is the sun minus the boresight along the axis, so a positive
error asks for a larger setpoint.  The axis's geometry (which camera component is the
error) lives in :mod:`.geometry`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from .fuzzy import FuzzyPID, FuzzyPIDGains
from .learner import OffsetLearner

MODES = ("assisted", "paper")


@dataclass(frozen=True)
class AxisCommand:
    """What the axis asks of its drive at one cycle."""

    setpoint_deg: float
    source: str  # "camera" (closed loop), "learned" (feed-forward), "hold"
    offset_deg: float  # the learned offset in use (0 in the paper's mode)
    correction_deg: float  # the PID's share of the setpoint


class ClosedLoopAxis:
    """Per-axis controller; ``update`` once per cycle (frame) with what was measured."""

    def __init__(
        self,
        *,
        mode: str = "assisted",
        gains: FuzzyPIDGains | None = None,
        learner: OffsetLearner | None = None,
        correction_decay_s: float = 600.0,
        max_error_deg: float = 90.0,
    ):
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        self.mode = mode
        self.pid = FuzzyPID(gains)
        self.learner = learner if learner is not None else OffsetLearner()
        self.correction_decay_s = correction_decay_s
        self.max_error_deg = max_error_deg
        self.setpoint: float | None = None
        self.correction = 0.0
        self._t: float | None = None

    def update(
        self,
        t: float,
        error_deg: float | None,
        position_deg: float,
        reference_deg: float | None = None,
        frame_reference_deg: float | None = None,
    ) -> AxisCommand:
        """One cycle at POSIX ``t``.

        ``error_deg``: the camera's offset of the sun along this axis (None: no sun seen);
        ``position_deg``: the drive's reported angle; ``reference_deg``: the open-loop angle
        for an aligned row (required in the assisted mode); ``frame_reference_deg``: that
        angle at the frame's time when the setpoint aims later (the loop's lead), for the
        offset's measurement (default: ``reference_deg``).
        """
        seen = error_deg is not None and math.isfinite(error_deg) and abs(error_deg) <= self.max_error_deg
        dt = 0.0 if self._t is None else max(t - self._t, 0.0)
        self._t = t
        if self.setpoint is None:
            self.setpoint = position_deg
        if self.mode == "paper" or reference_deg is None:
            if seen:
                assert error_deg is not None
                self.setpoint += self.pid.step(error_deg)
                return AxisCommand(self.setpoint, "camera", 0.0, 0.0)
            self.pid.reset()
            return AxisCommand(self.setpoint, "hold", 0.0, 0.0)
        before = self.learner.estimate_deg
        if seen:
            assert error_deg is not None
            at_frame = reference_deg if frame_reference_deg is None else frame_reference_deg
            self.learner.update(t, position_deg + error_deg - at_frame)
            # bumpless: what the learner took over leaves the correction
            self.correction += self.pid.step(error_deg) - (self.learner.estimate_deg - before)
            source = "camera"
        else:
            self.learner.predict(t)
            self.pid.reset()
            if self.correction_decay_s > 0 and dt > 0:
                self.correction *= math.exp(-dt / self.correction_decay_s)
            source = "learned"
        self.setpoint = reference_deg + self.learner.estimate_deg + self.correction
        return AxisCommand(self.setpoint, source, self.learner.estimate_deg, self.correction)
