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
  the row on the sun through the gap; so it does on a frame the learner refuses (a glint
  is no sun), and the correction holds while the drive is still on its way.

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
        max_offset_deg: float = 90.0,
    ):
        if mode not in MODES:
            raise ValueError(f"mode must be one of {MODES}, got {mode!r}")
        self.mode = mode
        self.pid = FuzzyPID(gains)
        self.learner = learner if learner is not None else OffsetLearner()
        self.correction_decay_s = correction_decay_s
        self.max_error_deg = max_error_deg
        self.max_offset_deg = max_offset_deg
        self.setpoint: float | None = None
        self.correction = 0.0
        self._t: float | None = None

    def seen(self, error_deg: float | None) -> bool:
        """Whether the camera's error is a sight this axis trusts (finite, within
        ``max_error_deg``)."""
        return error_deg is not None and math.isfinite(error_deg) and abs(error_deg) <= self.max_error_deg

    def plausible(self, error_deg: float | None, position_deg: float, frame_reference_deg: float) -> bool:
        """Whether the frame measures an offset this axis could have (``max_offset_deg``)."""
        if not self.seen(error_deg):
            return False
        assert error_deg is not None
        return abs(position_deg + error_deg - frame_reference_deg) <= self.max_offset_deg

    def admits(
        self, t: float, error_deg: float | None, position_deg: float, frame_reference_deg: float
    ) -> bool:
        """Whether the learner would take this frame's offset (assisted mode): a row refuses
        a frame that any of its axes refuses (a glint straight above the sun is off in
        elevation only, and is no sight of the sun in azimuth either)."""
        if not self.seen(error_deg):
            return False
        assert error_deg is not None
        return self.learner.admits(t, position_deg + error_deg - frame_reference_deg)

    def update(
        self,
        t: float,
        error_deg: float | None,
        position_deg: float,
        reference_deg: float | None = None,
        frame_reference_deg: float | None = None,
        *,
        veto: bool = False,
        settled: bool = True,
    ) -> AxisCommand:
        """One cycle at POSIX ``t``.

        ``error_deg``: the camera's offset of the sun along this axis (None: no sun seen);
        ``position_deg``: the drive's reported angle; ``reference_deg``: the open-loop angle
        for an aligned row (required in the assisted mode); ``frame_reference_deg``: that
        angle at the frame's time when the setpoint aims later (the loop's lead), for the
        offset's measurement (default: ``reference_deg``); ``veto``: another axis of the row
        refused the frame (assisted mode: it counts as refused here too); ``settled``: the
        drive has reached its last target (assisted mode: a frame taken on the way is not
        used, and the correction holds).
        """
        seen = self.seen(error_deg)
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
        if not settled:
            # on its way from stow or back from backtracking the drive lags its target by
            # degrees: that error is the slew's, not the pointing's, and a frame far off
            # the axis, taken while moving, measures the offset badly (three such frames
            # once taught the learner an offset 0.5 deg wrong, which then refused the right
            # ones for 20 frames while the PID, stepped on the slew, held the row 7 deg off)
            self.learner.predict(t)
            self.pid.reset()
            self.setpoint = reference_deg + self.learner.estimate_deg + self.correction
            return AxisCommand(self.setpoint, "settling", self.learner.estimate_deg, self.correction)
        before = self.learner.estimate_deg
        trusted = False
        if seen:
            assert error_deg is not None
            at_frame = reference_deg if frame_reference_deg is None else frame_reference_deg
            # a frame whose offset the learner refuses is no sight of the sun (a cloud's
            # sunlit edge, a glint): the PID must not chase it either.  One such frame had
            # stepped a row's correction by 3 deg, which then took half an hour to decay
            # (docs/fisheye.md, the panel loop under broken cloud).  A real change of the
            # offset is the learner's to take: it restarts after a run of refusals.
            trusted = self.learner.update(t, position_deg + error_deg - at_frame, veto=veto)
        if trusted:
            assert error_deg is not None
            # bumpless: what the learner took over leaves the correction
            self.correction += self.pid.step(error_deg) - (self.learner.estimate_deg - before)
            source = "camera"
        else:
            if not seen:
                self.learner.predict(t)
            self.pid.reset()
            if self.correction_decay_s > 0 and dt > 0:
                self.correction *= math.exp(-dt / self.correction_decay_s)
            source = "learned"
        self.setpoint = reference_deg + self.learner.estimate_deg + self.correction
        return AxisCommand(self.setpoint, source, self.learner.estimate_deg, self.correction)
