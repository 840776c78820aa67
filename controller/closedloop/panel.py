"""The panel-mounted closed loop in the control loop: a :class:`Controller` whose trackers
listed in ``[closedloop]`` are steered by the camera on their panel.

Each cycle at time ``t``, before the setpoints (:meth:`ClosedLoopController._observe`):

1. the drive's position is read (its encoder, at the frame's time);
2. the row's camera frame is measured by the default fisheye pipeline (the lens of the
   ``[closedloop] calibration`` bundle, no orientation: the camera moves with the panel,
   so every frame stands alone: no sequence gate, no motion vetoes), and the sun's
   camera-frame direction, turned into the panel's frame by the bundle's ``[mount]`` when
   it has one, becomes per-axis errors (:mod:`.geometry`);
3. the sun source's reference at ``t`` is kept for the offset's measurement.

Then (:meth:`ClosedLoopController.targets`), only in TRACK mode and with no stow order,
each axis's :class:`~.axis.ClosedLoopAxis` replaces the open-loop target: ``paper``, the
setpoint moves by the fuzzy PID's step; ``assisted``, reference + learned offset + the
PID's correction, using a frame only once the drive has reached its last target
(:data:`SETTLE_DEG`), only if its offset is one a row can have (``max_offset_deg``) and
only if the learner takes that offset on every axis of the row (a run of refusals restarts
the learner only on one offset, :data:`REFUSAL_SPREAD_DEG`).  Everything else is the plain
controller's: a weather stow, night stow,
DIFFUSE and an operator's manual setpoint outrank the loop, and every target is clamped to
the axis's limits on its way to the wire.  While a row backtracks, or its reference is at
an axis limit (the camera's error then is not a pointing error), it follows the reference
(plus the learned offset in the assisted mode) and the paper's loop restarts afterwards;
the assisted loop's learner still takes the offset from the sun seen off the camera's axis
there (:meth:`ClosedLoopController._learn_aside`).

The learned offsets persist in ``[closedloop] state`` (:class:`~.learner.MisalignmentStore`,
saved every simulated hour and at close).  Angles in degrees; errors are sun minus
boresight.
"""

from __future__ import annotations

import asyncio
import logging
import math
from collections import Counter
from collections.abc import Mapping
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from .. import setpoints as sp
from ..calibration.fisheye_bundle import FisheyeBundle, load_fisheye_bundle
from ..config import Config
from ..drives.base import DriveCommError
from ..geometry import lowest_sun_azimuth
from ..loop import Controller
from ..modes import ControlMode, ModeDecision
from ..records import TrackerRuntime
from ..safety import StowOrder, clamp_targets
from ..sun.camera import FrameSource
from ..sun.types import SunEstimate
from ..vision.fisheye import FisheyeEstimator, SeedEstimator
from ..vision.fisheye.pipeline import FramePipeline
from .axis import ClosedLoopAxis
from .learner import MisalignmentStore
from .pose import axis_names, camera_errors, expected_sun, sun_angles, unclipped_reference

log = logging.getLogger("heliotrack.closedloop")

#: A reference this close to an axis limit (deg) is not a pointing target for the camera.
LIMIT_MARGIN_DEG = 0.5
#: How often the learned offsets are saved (s of the controller's clock).
SAVE_EVERY_S = 3600.0
#: A drive farther than this (deg) from its last target is still on its way (assisted mode).
SETTLE_DEG = 0.5
#: Implausible frames counted up, plausible ones down by :data:`IMPLAUSIBLE_FORGIVE`: at this
#: count a row's camera is said to disagree with its pose (a camera turned on its panel, or
#: a reflection that stays; 30 min of 10-s frames).
IMPLAUSIBLE_WARN = 180
IMPLAUSIBLE_FORGIVE = 10
#: A run of refused frames is one new offset only while each stays this close (deg, every
#: axis) to the run's mean: a reflection's offset drifts at the sun's rate, a slip's does not.
REFUSAL_SPREAD_DEG = 0.3


@dataclass
class Measurement:
    """What one cycle measured of a row: at the frame's time ``t``."""

    t: float
    position: list[float]  # the drive's reported axis angles (deg)
    errors: list[float] | None  # the camera's per-axis errors (None: no sun seen)
    frame_reference: list[float] | None  # the sun source's reference at t
    frame_sun: list[float] | None = None  # the axes' angles that face the sun at t (unclipped)
    sigma_deg: float | None = None  # the camera's one-sigma of the sun's direction


@dataclass
class RowLoop:
    """One tracker's camera, estimator and axes."""

    runtime: TrackerRuntime
    frames: FrameSource
    estimator: FramePipeline  # the default pipeline, or the paper's ([closedloop] algorithm)
    axes: list[ClosedLoopAxis]
    mount: np.ndarray | None = None  # the camera on its panel: the bundle's [mount] (None: the normal)
    measured: Measurement | None = None
    active: bool = False  # steered by the loop in the previous cycle
    sent: list[float] | None = None  # the targets of the previous cycle, clamped (None: not ours)
    sent_t: float | None = None  # when a setpoint last went to the row (s, the controller's clock)
    refusals: list[list[float]] = field(default_factory=list)  # offsets of the refused run
    sources: Counter = field(default_factory=Counter)
    frames_seen: Counter = field(default_factory=Counter)
    last_source: str = ""  # what set this cycle's setpoint ("": not steered by the loop)
    framed_at: list[float] | None = None  # the drive's position at the previous frame (deg)
    implausible: int = 0  # implausible frames, less IMPLAUSIBLE_FORGIVE per plausible one

    def count(self, source: str) -> None:
        """This cycle's setpoint came from ``source`` (camera, learned, settling, hold, reference)."""
        self.sources[source] += 1
        self.last_source = source

    def restart(self) -> None:
        """Out of closed loop: the PID forgets its history, the paper's setpoint its value."""
        for ax in self.axes:
            ax.pid.reset()
            if ax.mode == "paper":
                ax.setpoint = None
        self.active = False
        self.sent = None

    def fresh(self, frame_t: float, t: float, period_s: float) -> bool:
        """A frame taken at ``frame_t`` shows the panel where it is at ``t``: taken after
        the row's last setpoint (within a period when there was none) and not after ``t``."""
        since = self.sent_t if self.sent_t is not None else t - period_s
        return since < frame_t <= t

    def settled(self, position: list[float]) -> bool:
        """The drive has reached the targets this loop sent it last cycle."""
        return self.sent is not None and all(abs(p - s) <= SETTLE_DEG for p, s in zip(position, self.sent))


class ClosedLoopController(Controller):
    """:class:`controller.loop.Controller` with the panel-mounted closed loop.

    ``panel_frames``: tracker name -> its panel camera's frames (the simulator's renderer).
    The other arguments are the :class:`Controller`'s.
    """

    def __init__(
        self,
        config: Config,
        *args: Any,
        panel_frames: Mapping[str, FrameSource],
        **kwargs: Any,
    ):
        super().__init__(config, *args, **kwargs)
        cl = config.closedloop
        if cl is None:
            raise ValueError("ClosedLoopController needs a [closedloop] table")
        self.closedloop = cl
        bundles: dict[Path, FisheyeBundle] = {}  # one camera model: one bundle, read once
        self.misalignment = MisalignmentStore(cl.state)
        if self.misalignment.note:
            log.warning("closed loop: %s", self.misalignment.note)
        names = set(cl.trackers) if cl.trackers else {tr.cfg.name for tr in self.trackers}
        max_err = cl.max_error_deg if cl.mode == "assisted" else 90.0
        self.rows: list[RowLoop] = []
        for tr in self.trackers:
            if tr.cfg.name not in names:
                continue
            if tr.cfg.name not in panel_frames:
                raise ValueError(f"{tr.cfg.name}: no panel camera frames")
            axes = [
                ClosedLoopAxis(
                    mode=cl.mode,
                    learner=self.misalignment.learner(tr.cfg.name, name),
                    max_error_deg=max_err,
                    max_offset_deg=cl.max_offset_deg,
                )
                for name in axis_names(tr.cfg)
            ]
            lens = cl.lens(tr.cfg.name)
            if lens not in bundles:
                bundles[lens] = load_fisheye_bundle(lens)
            make = SeedEstimator if cl.algorithm == "seed" else FisheyeEstimator
            mount = bundles[lens].mount
            if mount is not None:
                lean = math.degrees(math.acos(max(-1.0, min(1.0, float(mount.matrix[2, 2])))))
                log.info(
                    "closed loop: %s's camera sits %.3f deg off its panel's normal ([mount] of %s)",
                    tr.cfg.name,
                    lean,
                    lens,
                )
            self.rows.append(
                RowLoop(
                    tr,
                    panel_frames[tr.cfg.name],
                    make(bundles[lens]),
                    axes,
                    mount=mount.matrix if mount is not None else None,
                )
            )
            if any(ax.learner.accepted for ax in axes):
                log.info(
                    "closed loop: %s starts from its learned offset %s (%s)",
                    tr.cfg.name,
                    ", ".join(
                        f"{n} {ax.learner.estimate_deg:+.3f} deg" for n, ax in zip(axis_names(tr.cfg), axes)
                    ),
                    cl.state,
                )
        self._t = math.nan
        self._saved_at = -math.inf

    # -- measuring ------------------------------------------------------------------------
    async def _observe(self, t: float) -> None:
        await super()._observe(t)
        self._t = t
        est = self.sun.estimate(t, now=t)
        daylight = est is not None and est.el_deg > self.config.control.min_elevation_deg - 2.0
        for row in self.rows:
            row.measured = await self._measure(row, t, est) if daylight else None

    async def _measure(self, row: RowLoop, t: float, est: SunEstimate | None) -> Measurement | None:
        tr = row.runtime
        if not tr.configured:
            return None
        try:
            state = await asyncio.wait_for(tr.drive.read_state(), self._deadline())
        except (TimeoutError, DriveCommError) as exc:
            row.frames_seen["no position"] += 1
            log.debug("%s: position not read: %s", tr.cfg.name, exc)
            return None
        position = [a.actual_deg for a in state.axes][: tr.cfg.axes]
        seam = lowest_sun_azimuth(self.config.site.latitude)

        def reference_at(e: SunEstimate | None) -> list[float] | None:
            return sp.tracking(e, [tr.cfg], [state], seam)[0][0] if e is not None else None

        reference = reference_at(est)
        frame = await asyncio.to_thread(row.frames.grab, t)
        if frame is None:
            row.frames_seen["no frame"] += 1
            return Measurement(t, position, None, reference)
        if not row.fresh(frame.time, t, self.config.control.period_s):
            # taken before the row's last setpoint (a camera slower than the loop, or the
            # same frame again): its error is one the loop has already corrected
            row.frames_seen["stale frame"] += 1
            return Measurement(t, position, None, reference)
        sun = est
        if frame.time != t:  # a live camera's frame: the sun where it was when the frame was taken
            sun = self.sun.estimate(frame.time, now=t)
            reference = reference_at(sun)
        if row.framed_at is None or any(abs(p - q) > SETTLE_DEG for p, q in zip(position, row.framed_at)):
            # the camera turned: the sun's last centroid says nothing of where it is now in
            # the image (the paper's rule 3 holds for a camera that moved little between
            # frames; a slew from stow had locked the seed pipeline out for the day)
            row.estimator.reset_sequence()
        row.framed_at = position
        res = await asyncio.to_thread(row.estimator.estimate_image, frame.image, None)
        if res.reason == "ambiguous_candidates" and sun is not None and self.closedloop.mode == "assisted":
            # glares of one size (a reflection beside the sun): the one where the sun must be,
            # by the panel's pose (the drive's position less the learned offset)
            prior = expected_sun(tr.cfg, sun, position, row.axes, row.mount)
            res = await asyncio.to_thread(row.estimator.estimate_image, frame.image, None, prior)
            if res.found:
                row.frames_seen["chosen by the pose"] += 1
        if not res.found or res.d_cam is None:
            row.frames_seen[res.reason or "not found"] += 1
            return Measurement(t, position, None, reference)
        row.frames_seen["found"] += 1
        d_panel = res.d_cam if row.mount is None else row.mount @ res.d_cam
        return Measurement(
            t,
            position,
            camera_errors(tr.cfg, d_panel, position),
            reference,
            None if sun is None else sun_angles(tr.cfg, sun, position),
            res.sigma_deg,
        )

    # -- steering -------------------------------------------------------------------------
    def targets(
        self, est: SunEstimate | None, decision: ModeDecision, order: StowOrder | None
    ) -> list[sp.Setpoint]:
        out = super().targets(est, decision, order)
        tracking = order is None and decision.mode == ControlMode.TRACK
        for row in self.rows:
            i = row.runtime.index
            if math.isfinite(self._t):
                row.sent_t = self._t  # whatever this cycle sends may move the panel
            row.last_source = ""
            if not tracking:
                row.restart()
                continue
            wide = unclipped_reference(row.runtime.cfg, est) if est is not None else None
            out[i] = self._steer(row, out[i], wide)
        if math.isfinite(self._t) and self._t - self._saved_at >= SAVE_EVERY_S:
            self._save()
        return out

    def _steer(self, row: RowLoop, base: sp.Setpoint, wide: list[float] | None = None) -> sp.Setpoint:
        """``base`` (the plain controller's targets) steered by the row's camera; ``wide``,
        a row's reference with no limit (:func:`.pose.unclipped_reference`)."""
        cfg = row.runtime.cfg
        reference, backtracking = base
        m = row.measured
        near_limit = any(
            min(abs(r - lo), abs(hi - r)) < LIMIT_MARGIN_DEG
            for r, (lo, hi) in zip(reference, cfg.soft_limits)
        )
        assisted = self.closedloop.mode == "assisted"
        if m is None or backtracking or near_limit:
            # no position, or a reference the camera cannot judge: follow the reference
            settled = m is not None and row.settled(m.position)
            row.restart()
            if assisted:
                if m is None or not settled or not self._learn_aside(row, m):
                    for ax in row.axes:
                        ax.learner.predict(self._t)
                row.count("learned")
                # the limit is the drive's: the offset is added before it clips
                ref = wide if wide is not None else reference
                follow = clamp_targets(cfg, [r + ax.learner.estimate_deg for r, ax in zip(ref, row.axes)])
                row.sent = follow
                return follow, backtracking
            row.count("reference")
            return reference, backtracking
        if not row.active:
            for ax, p in zip(row.axes, m.position):
                if ax.mode == "paper":
                    ax.setpoint = p
        targets = []
        source = "hold"
        frefs = m.frame_reference if m.frame_reference is not None else reference
        settled = row.settled(m.position)
        errors = m.errors
        if (
            assisted
            and settled
            and errors is not None
            and not all(ax.plausible(e, p, f) for ax, e, p, f in zip(row.axes, errors, m.position, frefs))
        ):
            # an offset no row has (a reflection that stays lit while a cloud hides the sun):
            # not even a refusal, or a run of them would restart the learner on the reflection
            # and steer the row onto it (docs/fisheye.md, the panel loop and a reflection)
            row.frames_seen["implausible"] += 1
            self._count_implausible(row, max(abs(p + e - f) for e, p, f in zip(errors, m.position, frefs)))
            errors = None
        elif assisted and settled and errors is not None:
            row.implausible = max(0, row.implausible - IMPLAUSIBLE_FORGIVE)
        veto = (
            assisted
            and settled
            and errors is not None
            and not all(ax.admits(m.t, e, p, f) for ax, e, p, f in zip(row.axes, errors, m.position, frefs))
        )
        if veto:
            row.frames_seen["refused"] += 1  # found, but no sight of the sun by the learned offset
            assert errors is not None
            self._count_refusal(row, [p + e - f for e, p, f in zip(errors, m.position, frefs)])
        elif errors is not None and settled:
            row.refusals.clear()  # the learners take this frame: their runs end
        for k, ax in enumerate(row.axes):
            err = errors[k] if errors is not None else None
            if assisted:
                cmd = ax.update(m.t, err, m.position[k], reference[k], frefs[k], veto=veto, settled=settled)
            else:
                cmd = ax.update(m.t, err, m.position[k])
            source = cmd.source
            targets.append(cmd.setpoint_deg)
        clamped = clamp_targets(cfg, targets)
        for ax, c, t in zip(row.axes, clamped, targets, strict=True):
            if ax.mode == "paper":
                ax.setpoint = c  # no wind-up beyond the limits
            elif t != c and ax.correction * (t - c) > 0:
                # anti-windup: the correction gives up what pushes past the limit (it had
                # integrated the error the limit holds, and carried it into the next cloud
                # gap: a row 1.6 deg off for an hour at Cape Town in June, an audit found);
                # the learned offset past the limit stays, the limit's own due
                ax.correction -= math.copysign(min(abs(t - c), abs(ax.correction)), t - c)
        row.active = True
        row.sent = clamped
        row.count(source)
        return clamped, backtracking

    def _learn_aside(self, row: RowLoop, m: Measurement) -> bool:
        """A frame taken, the drive settled, while the row backtracks or waits at a limit:
        the panel looks away from the sun on purpose, but its camera still sees it, and
        ``position + error`` less the angles that face the sun (:func:`sun_angles`) is the
        offset as in tracking.  The learner takes it at the camera's own sigma (a sun far
        off the axis is measured less well), with the same gates; the PID does not run.
        Whether the learner took it."""
        if m.errors is None or m.frame_sun is None:
            return False
        if not all(ax.seen(e) for ax, e in zip(row.axes, m.errors)):
            return False  # a sun this far off the camera's axis is not measured well enough
        suns = m.frame_sun
        if not all(ax.plausible(e, p, f) for ax, e, p, f in zip(row.axes, m.errors, m.position, suns)):
            # not counted towards the warning of a camera at odds with its pose, which
            # speaks of the frames it steers by: aside the sun, a reflection or a cloud's
            # glare in a gap may lie nearer the camera's axis than the sun
            row.frames_seen["implausible aside"] += 1
            return False
        offsets = [p + e - f for e, p, f in zip(m.errors, m.position, suns)]
        sigma = m.sigma_deg
        if not all(ax.learner.admits(m.t, z, sigma_deg=sigma) for ax, z in zip(row.axes, offsets)):
            # no refusal run either: a run restarts the learner, which only frames of the
            # sun on the axis may do (an off-axis bias must not teach it a new offset)
            row.frames_seen["refused aside"] += 1
            return False
        row.refusals.clear()
        for ax, z in zip(row.axes, offsets):
            ax.learner.update(m.t, z, sigma_deg=sigma)
        row.frames_seen["aside"] += 1
        log.debug("%s: offset %s measured aside the sun (sigma %s deg)", row.runtime.cfg.name, offsets, sigma)
        return True

    def _count_implausible(self, row: RowLoop, offset_deg: float) -> None:
        """Say once, when implausible frames keep coming, what usually causes them."""
        row.implausible += 1
        if row.implausible == IMPLAUSIBLE_WARN:
            log.warning(
                "closed loop: %s: its camera keeps measuring offsets no row has (%.1f deg, over "
                "max_offset_deg %g): a camera turned on its panel (upside down, or a quarter turn) "
                "without its [mount] in %s (heliotrack calibrate fisheye mount), or a reflection "
                "that stays in view",
                row.runtime.cfg.name,
                offset_deg,
                self.closedloop.max_offset_deg,
                self.closedloop.lens(row.runtime.cfg.name),
            )

    @staticmethod
    def _count_refusal(row: RowLoop, offsets: list[float]) -> None:
        """Keep a run of refusals going (the learners restart on its 20th) only while its
        frames agree on one offset on every axis; otherwise this frame starts a new run.
        Without this, a reflection lit while a cloud hid the sun restarted a row's learner
        on itself and steered the row 5 deg off for 16 minutes (docs/fisheye.md)."""
        if row.refusals:
            mean = [sum(z) / len(row.refusals) for z in zip(*row.refusals)]
            if any(abs(z - c) > REFUSAL_SPREAD_DEG for z, c in zip(offsets, mean)):
                row.refusals.clear()
                for ax in row.axes:
                    ax.learner.refused_run = 0  # this frame's refusal starts the run anew
        row.refusals.append(offsets)

    # -- persistence and figures ------------------------------------------------------------
    def _save(self) -> None:
        self._saved_at = self._t
        if self.misalignment.path is None:
            return
        try:
            self.misalignment.save()
        except OSError as exc:
            log.warning("closed loop: learned offsets not saved: %s", exc)

    def closedloop_cycle(self) -> dict[str, str]:
        """What set each looped row's setpoint this cycle, by tracker (rows the loop did not
        steer, in a stow or at night, are left out)."""
        return {row.runtime.cfg.name: row.last_source for row in self.rows if row.last_source}

    def closedloop_summary(self) -> dict[str, Any]:
        """The loop's mode and pipeline, and per row: learned offsets, sources of its
        setpoints, frames."""
        rows = {}
        for row in self.rows:
            names = axis_names(row.runtime.cfg)
            rows[row.runtime.cfg.name] = {
                "learned_offset_deg": {
                    n: round(ax.learner.estimate_deg, 5) for n, ax in zip(names, row.axes)
                },
                "learned_sigma_deg": {n: round(ax.learner.sigma_deg, 5) for n, ax in zip(names, row.axes)},
                "setpoints": dict(row.sources),
                "frames": dict(row.frames_seen),
            }
        return {"mode": self.closedloop.mode, "algorithm": self.closedloop.algorithm, "rows": rows}

    async def close(self) -> None:
        self._save()
        await super().close()
