"""ClosedLoopController's steering, without drives or cameras: what it does with a cycle's
measurement, and what outranks it."""

from __future__ import annotations

from dataclasses import replace
from datetime import UTC, datetime
from unittest import mock

import pytest

from controller.clock import SimClock
from controller.closedloop.panel import ClosedLoopController, Measurement
from controller.loop import Controller
from controller.modes import ControlMode, ModeDecision
from controller.safety import StowOrder
from controller.sun.camera import FrameSource
from controller.sun.source import EphemerisSource
from heliotrack.scenario import load_scenario
from tests.conftest import REPO

T = datetime(2024, 3, 20, 8, 0, tzinfo=UTC).timestamp()


def controller(mode: str = "assisted", **closedloop: str) -> ClosedLoopController:
    """The clear day's controller, its ``[closedloop]`` in ``mode`` with ``closedloop``'s
    other keys changed."""
    from dataclasses import replace

    cfg = load_scenario(REPO / "config" / "hil-closedloop.toml")
    assert cfg.closedloop is not None
    cfg = replace(cfg, closedloop=replace(cfg.closedloop, mode=mode, **closedloop))
    frames = {tr.name: mock.Mock(spec=FrameSource) for tr in cfg.trackers}
    drives = {tr.name: mock.Mock() for tr in cfg.trackers}
    ctl = ClosedLoopController(cfg, drives, EphemerisSource(cfg.site), SimClock(T), panel_frames=frames)
    ctl._t = T
    return ctl


def base_targets(ctl: ClosedLoopController):
    est = ctl.sun.estimate(T)
    return est, ctl.targets(est, ModeDecision(ControlMode.TRACK, "sun up"), None)


def test_a_stow_order_and_other_modes_are_not_steered():
    ctl = controller()
    est = ctl.sun.estimate(T)
    for row in ctl.rows:
        row.measured = Measurement(
            T, [0.0, 0.0][: row.runtime.cfg.axes], [5.0, 5.0][: row.runtime.cfg.axes], None
        )
    stow = ctl.targets(est, ModeDecision(ControlMode.STOW, "wind"), StowOrder("wind", "gust"))
    assert [t for t, _ in stow] == [list(ctl.safety.angles(tr.cfg, "wind")) for tr in ctl.trackers]
    diffuse = ctl.targets(est, ModeDecision(ControlMode.DIFFUSE, "overcast"), None)
    assert diffuse[1][0] == [0.0]


def test_assisted_adds_the_learned_offset_and_the_correction_to_the_reference():
    ctl = controller()
    est = ctl.sun.estimate(T)
    row = next(r for r in ctl.rows if r.runtime.cfg.name == "row-1")
    ref = Controller.targets(ctl, est, ModeDecision(ControlMode.TRACK, "sun up"), None)[1][0][0]
    # the loop's first cycle only sends the drive its target: no frame is used on the way
    row.measured = Measurement(T, [ref - 20.0], [21.5], [ref])
    _, out = base_targets(ctl)
    assert out[1][0][0] == pytest.approx(ref) and row.axes[0].learner.accepted == 0
    # the panel sits at the reference, and the camera sees the sun 1.5 deg further on
    row.measured = Measurement(T, [ref], [1.5], [ref])
    _, out = base_targets(ctl)
    learned = row.axes[0].learner.estimate_deg
    assert learned == pytest.approx(1.5, abs=0.01)  # one frame: the prior is wide
    assert out[1][0][0] == pytest.approx(ref + learned + row.axes[0].correction, abs=1e-9)
    # bumpless: the learner's jump is not added to the PID's own step towards the sun
    assert ref + 0.5 < out[1][0][0] <= ref + 1.5
    # no sun now: reference + learned offset (the correction decays)
    row.measured = Measurement(T + 10, [ref + 1.5], None, [ref])
    ctl._t = T + 10
    _, out = base_targets(ctl)
    assert out[1][0][0] == pytest.approx(ref + learned + row.axes[0].correction, abs=1e-9)
    assert row.sources == {"settling": 1, "camera": 1, "learned": 1}


def test_the_papers_setpoint_is_held_inside_the_limits():
    ctl = controller("paper")
    row = next(r for r in ctl.rows if r.runtime.cfg.name == "row-1")
    lim = row.runtime.cfg.soft_limits[0][1]
    for k in range(30):  # the camera keeps asking for more than the row can turn
        row.measured = Measurement(T + 10 * k, [lim - 0.6], [10.0], None)
        ctl._t = T + 10 * k
        _, out = base_targets(ctl)
    assert out[1][0][0] <= lim
    assert row.axes[0].setpoint is not None and row.axes[0].setpoint <= lim


def test_the_assisted_correction_does_not_wind_up_against_a_limit():
    """A reference just inside the row's limit and a panel 1.5 deg off: reference + offset
    lies past the limit, the clamp holds the row there, and the camera's residual had been
    integrated without bound (an audit: the row 1.6 deg off through the next cloud gap)."""
    from dataclasses import replace

    ctl = controller()
    row = next(r for r in ctl.rows if r.runtime.cfg.name == "row-1")
    est = ctl.sun.estimate(T)
    ref = Controller.targets(ctl, est, ModeDecision(ControlMode.TRACK, "sun up"), None)[1][0][0]
    side = 1.0 if ref > 0 else -1.0  # the row's limits are +-max_angle: the one on ref's side
    row.runtime.cfg = replace(row.runtime.cfg, max_angle=abs(ref) + 0.7)
    pos = ref
    for k in range(60):  # ten minutes of frames; the panel sits 1.5 deg behind its shaft
        row.measured = Measurement(T + 10 * k, [pos], [ref - pos + 1.5 * side], [ref])
        ctl._t = T + 10 * k
        _, out = base_targets(ctl)
        pos = out[1][0][0]
        assert side * pos <= abs(ref) + 0.7 + 1e-9
    assert row.axes[0].learner.estimate_deg == pytest.approx(1.5 * side, abs=0.05)
    assert abs(row.axes[0].correction) < 0.5, row.axes[0].correction


def dual_axis_row(ctl: ClosedLoopController):
    """The dual-axis tracker's loop and its reference (az, el) at T."""
    row = next(r for r in ctl.rows if r.runtime.cfg.name == "dual-1")
    est = ctl.sun.estimate(T)
    return row, Controller.targets(ctl, est, ModeDecision(ControlMode.TRACK, "sun up"), None)[0][0]


def test_a_glint_refused_on_one_axis_is_refused_on_the_other():
    ctl = controller()
    row, ref = dual_axis_row(ctl)
    az, el = row.axes
    for k in range(31):  # the row has learned that it sits on the sun (the first: settling)
        ctl._t = T + 10 * k
        row.measured = Measurement(ctl._t, list(ref), [0.0, 0.0], list(ref))
        base_targets(ctl)
    assert az.learner.learned and el.learner.learned
    az_before, az_refused = az.correction, az.learner.refused
    # a sunlit cloud edge straight above the sun: on the sun in azimuth, 4 deg off in elevation
    ctl._t = T + 300
    row.measured = Measurement(ctl._t, list(ref), [0.05, 4.0], list(ref))
    base_targets(ctl)
    assert el.learner.refused == 1 and az.learner.refused == az_refused + 1
    assert az.correction == pytest.approx(az_before)  # the PID did not step on it either
    assert abs(el.correction) < 0.01
    assert row.frames_seen["refused"] == 1


def test_a_frame_taken_while_the_drive_is_on_its_way_is_not_used():
    ctl = controller()
    row, ref = dual_axis_row(ctl)
    az, el = row.axes
    for k in range(12):  # coming from stow, face up: 1 deg a cycle closer, the sun far off the axis
        ctl._t = T + 10 * k
        pos = [ref[0] - 12.0 + k, ref[1] + 12.0 - k]
        row.measured = Measurement(ctl._t, pos, [ref[0] - pos[0] + 0.4, ref[1] - pos[1] - 0.6], list(ref))
        _, out = base_targets(ctl)
        assert out[0][0] == pytest.approx(list(ref))  # the target, no correction stepped on the slew
    assert az.learner.accepted == 0 and el.learner.accepted == 0
    assert row.sources == {"settling": 12}
    ctl._t = T + 120  # arrived: the frame measures the offset
    row.measured = Measurement(ctl._t, list(ref), [0.4, -0.6], list(ref))
    base_targets(ctl)
    assert az.learner.estimate_deg == pytest.approx(0.4, abs=0.01)
    assert el.learner.estimate_deg == pytest.approx(-0.6, abs=0.01)


@pytest.mark.parametrize("drift, restarts", [(0.0, True), (0.04, False)])
def test_a_run_of_refusals_restarts_the_learner_only_on_one_offset(drift, restarts):
    # 25 refused frames 3 deg off the learned offset: a panel that slipped gives the same
    # offset each time (the learner restarts on it); a reflection lit while a cloud hides the
    # sun gives one that moves at the sun's rate (0.04 deg a 10-s frame): never a restart
    ctl = controller()
    row, ref = dual_axis_row(ctl)
    for k in range(31):
        ctl._t = T + 10 * k
        row.measured = Measurement(ctl._t, list(ref), [0.0, 0.0], list(ref))
        base_targets(ctl)
    for k in range(25):
        ctl._t = T + 310 + 10 * k
        row.measured = Measurement(ctl._t, list(ref), [3.0 + drift * k, 1.0 - drift * k], list(ref))
        base_targets(ctl)
    az, el = row.axes
    assert row.frames_seen["refused"] >= 20
    if restarts:
        assert az.learner.estimate_deg == pytest.approx(3.0, abs=0.05)
        assert el.learner.estimate_deg == pytest.approx(1.0, abs=0.05)
    else:
        assert az.learner.estimate_deg == pytest.approx(0.0, abs=0.01)
        assert el.learner.estimate_deg == pytest.approx(0.0, abs=0.01)


def test_a_frame_measuring_an_offset_no_row_has_is_not_even_a_refusal():
    ctl = controller()
    row, ref = dual_axis_row(ctl)
    az, el = row.axes
    for k in range(60):  # a reflection 20 deg off, lit for ten minutes while a cloud hides the sun
        ctl._t = T + 10 * k
        row.measured = Measurement(ctl._t, list(ref), [20.0, -3.0], list(ref))
        _, out = base_targets(ctl)
    assert out[0][0] == pytest.approx(list(ref))  # the reference and the (unlearned) offset
    assert az.learner.accepted == 0 and az.learner.refused == 0 and el.learner.refused == 0
    assert row.frames_seen["implausible"] == 59  # the first cycle was the drive's settling


def row_state(angle: float):
    from controller.drives.base import AxisState, DriveState
    from firmware_protocol import Fault, Mode, Status

    axis = AxisState(angle, angle, 0.0, Status.AT_TARGET, Fault(0), Mode.AUTO)
    return DriveState(1, (axis,))


@pytest.mark.parametrize(
    ("frame_dt", "used"),
    [(-5.0, True), (-12.0, False), (-25.0, False), (1.0, False)],
    ids=["after the last setpoint", "before it", "the frame before that", "from the future"],
)
def test_a_live_cameras_frame_is_used_only_if_taken_since_the_last_setpoint(frame_dt, used):
    """A real camera's frame carries its own time: one taken before the row's last setpoint
    (a camera slower than the loop, the same file read twice) shows an error the loop has
    already corrected, and stepping on it again overshoots."""
    import asyncio

    import numpy as np

    from controller.sun.camera import CameraFrame

    ctl = controller()
    row = next(r for r in ctl.rows if r.runtime.cfg.name == "row-1")
    row.runtime.drive.read_state = mock.AsyncMock(return_value=row_state(10.0))
    row.runtime.configured = True
    t = T + 10.0
    row.sent_t = T  # the last cycle's setpoint went at T
    image = np.zeros((240, 320, 3), np.uint8)
    row.frames.grab.return_value = CameraFrame(image, t + frame_dt, "f.png")
    row.estimator = mock.Mock()
    row.estimator.estimate_image.return_value = mock.Mock(found=False, d_cam=None, reason="no_sun_glare")
    m = asyncio.run(ctl._measure(row, t, ctl.sun.estimate(t)))
    assert m is not None and m.errors is None
    assert row.estimator.estimate_image.called is used
    assert row.frames_seen == ({"no_sun_glare": 1} if used else {"stale frame": 1})


def test_a_frame_is_measured_against_the_sun_at_its_own_time():
    """The offset a frame measures is the panel's position minus where the sun stood when
    the frame was taken, not at the cycle's time (10 s later the sun has moved 0.04 deg)."""
    import asyncio

    import numpy as np

    from controller.sun.camera import CameraFrame

    ctl = controller()
    row = next(r for r in ctl.rows if r.runtime.cfg.name == "row-1")
    t = T + 10.0
    ref_then = Controller.targets(ctl, ctl.sun.estimate(t - 9.0), ModeDecision(ControlMode.TRACK, "up"), None)
    ref_now = Controller.targets(ctl, ctl.sun.estimate(t), ModeDecision(ControlMode.TRACK, "up"), None)
    assert abs(ref_then[1][0][0] - ref_now[1][0][0]) > 0.02
    row.runtime.drive.read_state = mock.AsyncMock(return_value=row_state(ref_now[1][0][0]))
    row.runtime.configured = True
    row.sent_t = T
    row.frames.grab.return_value = CameraFrame(np.zeros((240, 320, 3), np.uint8), t - 9.0, "f.png")
    row.estimator = mock.Mock()
    row.estimator.estimate_image.return_value = mock.Mock(
        found=True, d_cam=np.array([np.sin(np.radians(0.7)), 0.0, np.cos(np.radians(0.7))])
    )
    m = asyncio.run(ctl._measure(row, t, ctl.sun.estimate(t)))
    assert m is not None and m.frame_reference == pytest.approx(ref_then[1][0], abs=1e-9)
    assert m.errors == pytest.approx([0.7], abs=1e-6)


def test_each_panel_camera_is_read_through_its_own_lens(tmp_path):
    """``[closedloop] calibration`` with "{tracker}": a unit whose principal point sits 0.6 px
    off the model's has its boresight 0.4 deg away, which only its own bundle knows."""

    lens = REPO / "config" / "calibration" / "panel-fisheye.toml"
    (tmp_path / "panel-dual-1.toml").write_text(lens.read_text())
    (tmp_path / "panel-row-1.toml").write_text(lens.read_text().replace("cx = 159.5", "cx = 160.1"))
    ctl = controller(calibration=str(tmp_path / "panel-{tracker}.toml"))
    cx = {r.runtime.cfg.name: r.estimator.lens.cx for r in ctl.rows}
    assert cx == {"dual-1": 159.5, "row-1": 160.1}


def test_the_papers_pipeline_on_a_camera_that_turned_starts_a_new_sequence():
    """``algorithm = "seed"``: the paper's rule 3 (the centroid near the last one) holds for a
    camera that moved little between frames.  A panel that slewed further (from stow, to
    the reference) would leave the last centroid far from the sun's place in the image, and
    the rule refused every frame after it for the rest of the day."""
    import asyncio

    import numpy as np

    from controller.sun.camera import CameraFrame
    from controller.vision.fisheye import SeedEstimator

    ctl = controller("paper", algorithm="seed")
    row = next(r for r in ctl.rows if r.runtime.cfg.name == "row-1")
    assert isinstance(row.estimator, SeedEstimator)
    row.runtime.configured = True
    row.estimator = mock.Mock(wraps=row.estimator)
    restarts = []
    for k, angle in enumerate((10.0, 10.3, 10.6, 25.0, 25.2)):
        t = T + 10.0 * (k + 1)
        row.sent_t = t - 10.0
        row.runtime.drive.read_state = mock.AsyncMock(return_value=row_state(angle))
        row.frames.grab.return_value = CameraFrame(np.zeros((240, 320, 3), np.uint8), t, "f.png")
        before = row.estimator.reset_sequence.call_count
        asyncio.run(ctl._measure(row, t, ctl.sun.estimate(t)))
        restarts.append(row.estimator.reset_sequence.call_count > before)
    assert restarts == [True, False, False, True, False]  # 0.3 deg a frame: one sequence


def test_the_pose_places_the_sun_through_the_cameras_mount():
    """Where the sun must lie in a turned camera: the panel's pose, then the mount."""
    from types import SimpleNamespace

    from scipy.spatial.transform import Rotation

    from controller.closedloop.geometry import row_normal, single_axis_error
    from controller.closedloop.pose import expected_sun
    from controller.sun.types import SunEstimate, enu_to_azel

    cfg = load_scenario(REPO / "config" / "hil-closedloop.toml")
    row = next(tr for tr in cfg.trackers if tr.name == "row-1")
    az, el = enu_to_azel(row_normal(21.0, row.axis_azimuth, row.axis_tilt))  # the sun 1 deg of rotation ahead
    sun = SunEstimate(0.0, float(az), float(el))
    axes = [SimpleNamespace(learner=SimpleNamespace(estimate_deg=0.0, variance=0.0))]
    plain = expected_sun(row, sun, [20.0], axes)  # type: ignore[arg-type]
    assert single_axis_error(plain.d_cam) == pytest.approx(1.0, abs=1e-3)
    mount = Rotation.from_rotvec([0.0, 0.8, 0.0], degrees=True).as_matrix()  # its axis 0.8 deg towards +x
    turned = expected_sun(row, sun, [20.0], axes, mount)  # type: ignore[arg-type]
    assert single_axis_error(turned.d_cam) == pytest.approx(0.2, abs=1e-3)


def test_a_backtracking_row_learns_its_offset_from_the_sun_off_its_camera_axis():
    """The panel looks 30 deg away from the sun on purpose; its camera still measures the
    offset against the angle that faces the sun, at the camera's sigma, without the PID;
    frames of a sun too far off the axis, or that the learner refuses, are left out, and
    refusals aside the sun never restart the learner (an off-axis bias is no slipped panel)."""
    from controller.closedloop.pose import sun_angles

    ctl = controller()
    row = next(r for r in ctl.rows if r.runtime.cfg.name == "row-1")
    (lr,) = [ax.learner for ax in row.axes]
    est = ctl.sun.estimate(T)

    def cycle(k: int, error_from_offset: float, look_away: float = 30.0) -> list[float]:
        ctl._t = T + 10 * k
        facing = sun_angles(row.runtime.cfg, est, [0.0])[0]
        ref = facing + look_away  # a backtracking angle
        pos = row.sent if row.sent is not None else [ref]
        error = facing - pos[0] + error_from_offset  # the panel sits 1.5 deg beyond its encoder
        row.measured = Measurement(ctl._t, list(pos), [error], [ref], [facing], 0.03)
        target, backtracking = ctl._steer(row, ([ref], True))
        assert backtracking
        return target

    for k in range(20):
        cycle(k, -1.5)
    assert lr.estimate_deg == pytest.approx(-1.5, abs=0.01)
    assert row.frames_seen["aside"] == 19  # the first cycle: no setpoint yet, not settled
    assert all(ax.correction == 0.0 for ax in row.axes)
    for k in range(20, 50):  # 3 deg off what was learned, run after run: never a restart
        cycle(k, 1.5)
    assert lr.estimate_deg == pytest.approx(-1.5, abs=0.01) and lr.refused_run == 0
    assert row.frames_seen["refused aside"] == 30
    cycle(50, -1.5, look_away=65.0)  # the row turns further away...
    accepted = lr.accepted
    cycle(51, -1.5, look_away=65.0)  # ...and sees the sun 65 deg off its axis: not measured well enough
    assert lr.accepted == accepted and row.frames_seen["aside"] == 20
    for k in range(52, 52 + 200):  # a reflection 30 deg from the sun, nearer the axis: no offset, no warning
        cycle(k, 30.0)
    assert row.frames_seen["implausible aside"] == 200 and row.implausible == 0
    assert lr.accepted == accepted


def test_at_its_limit_a_row_adds_its_learned_offset_before_the_drives_limit_clips():
    """The limit is the drive's, not the panel's: a panel 1.5 deg beyond its shaft (learned
    offset -1.5) faces a sun 0.8 deg past ``max_angle`` with the shaft 0.7 deg inside it,
    and a sun farther out with the shaft at the limit; the reference the plain controller
    clipped would have left the panel at ``max_angle``, 0.8 deg short (the panel loop's
    evening at Andimeshk: 1.44 deg)."""
    from controller.closedloop.pose import sun_angles, unclipped_reference

    ctl = controller()
    row = next(r for r in ctl.rows if r.runtime.cfg.name == "row-1")
    (lr,) = [ax.learner for ax in row.axes]
    for k in range(30):
        lr.update(T + 10 * k, -1.5, sigma_deg=0.03)
    limit = row.runtime.cfg.max_angle
    ctl._t = T + 300
    row.measured = None  # no position this cycle: the row follows its reference
    target, _ = ctl._steer(row, ([limit], False), [limit + 0.8])
    assert target == [pytest.approx(limit + 0.8 + lr.estimate_deg)] and target[0] < limit
    assert ctl._steer(row, ([limit], False), [limit + 3.0])[0] == [limit]
    assert ctl._steer(row, ([limit], False))[0] == [pytest.approx(limit + lr.estimate_deg)]  # as before
    # the unclipped reference of a row that does not backtrack is the angle facing the sun
    cfg = row.runtime.cfg
    est = ctl.sun.estimate(T)
    flat = replace(cfg, backtrack=False)
    assert unclipped_reference(flat, est) == [pytest.approx(sun_angles(flat, est, [0.0])[0], abs=1e-6)]
