"""The world's camera on a panel: its mounting agrees with the controller's convention,
its frame follows the panel, and a drive's mounting offset moves the panel, not the shaft."""

from __future__ import annotations

import math

import numpy as np
import pytest

from controller.closedloop.geometry import (
    dual_axis_enu_from_camera,
    dual_axis_errors,
    row_enu_from_camera,
    single_axis_error,
)
from hil import truth
from hil.camera import Site
from hil.drive import AxisParams, DriveFirmware
from hil.panelcam import PanelCamera, dual_axis_camera, row_camera

T = 1710928800.0 + 4 * 3600  # 2024-03-20 08:00 UTC


@pytest.mark.parametrize("az, el", [(100.0, 20.0), (180.0, 55.0), (250.0, 5.0), (10.0, 80.0)])
def test_dual_axis_mounting_is_the_controllers_convention(az, el):
    R = dual_axis_camera(az, el)
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-9)
    assert np.allclose(R[:, 2], truth.unit_from_azel(az, el), atol=1e-9)
    assert np.allclose(R, dual_axis_enu_from_camera(az, el), atol=1e-6)
    # a sun 0.7 deg further in azimuth and 0.4 deg lower: the controller reads exactly that
    d_cam = R.T @ truth.unit_from_azel(az + 0.7, el - 0.4)
    e_az, e_el = dual_axis_errors(d_cam, az, el)
    assert e_az == pytest.approx(0.7, abs=1e-6) and e_el == pytest.approx(-0.4, abs=1e-6)


@pytest.mark.parametrize("rot, axis_az, tilt", [(0.0, 180.0, 0.0), (-40.0, 180.0, 0.0), (30.0, 170.0, 5.0)])
def test_row_mounting_gives_the_rotation_error_with_its_sign(rot, axis_az, tilt):
    R = row_camera(rot, axis_az, tilt)
    assert np.allclose(R.T @ R, np.eye(3), atol=1e-9)
    assert np.allclose(R[:, 2], truth.row_normal(rot, axis_az, tilt), atol=1e-9)
    # the sun where the row would face at rot + 1.2 deg: a positive error of 1.2 deg
    sun = truth.row_normal(rot + 1.2, axis_az, tilt)
    assert single_axis_error(R.T @ sun) == pytest.approx(1.2, abs=1e-6)
    # the controller's own mounting of a row's camera (from pvlib's row geometry) is the world's
    assert np.allclose(R, row_enu_from_camera(rot, axis_az, tilt), atol=1e-6)


def _glare_centre(img: np.ndarray) -> tuple[float, float] | None:
    grey = img.min(axis=2).astype(float)
    ys, xs = np.nonzero(grey >= grey.max() - 4)
    if grey.max() < 200:
        return None
    return float(xs.mean()), float(ys.mean())


def test_the_sun_on_the_normal_is_at_the_image_centre_and_a_gap_hides_it():
    site = Site(32.4835, 48.3364, 150.0)
    cam = PanelCamera("dual-axis", site, noise=False)
    sun = truth.sun_truth(np.array([T]), site.latitude, site.longitude, site.altitude)
    az, el = float(sun.azimuth[0]), float(sun.elevation[0])
    lens = cam.scene.lens
    c = _glare_centre(cam.render(T, [az, el], 1.0))
    assert c is not None
    assert math.hypot(c[0] - lens.cx, c[1] - lens.cy) < 1.0
    # 5 deg off in elevation: the glare moves up the image (y towards decreasing elevation)
    c2 = _glare_centre(cam.render(T, [az, el - 5.0], 1.0))
    assert c2 is not None and c2[1] < lens.cy - 5
    assert _glare_centre(cam.render(T, [az, el], 0.0)) is None


def test_a_camera_turned_on_its_panel_sees_the_sun_off_its_axis():
    """Turned [0, 2, 0] deg on a panel facing the sun: its axis leans 2 deg towards +x, so
    the sun on the panel's normal lies 2 deg towards -x in the image (and the row's loop,
    centring it, would leave the panel 2 deg off)."""
    site = Site(32.4835, 48.3364, 150.0)
    sun = truth.sun_truth(np.array([T]), site.latitude, site.longitude, site.altitude)
    az, el = float(sun.azimuth[0]), float(sun.elevation[0])
    turned = PanelCamera("dual-axis", site, noise=False, mount_deg=(0.0, 2.0, 0.0))
    d_cam = turned.enu_from_camera([az, el]).T @ truth.unit_from_azel(az, el)
    assert single_axis_error(d_cam) == pytest.approx(-2.0, abs=1e-6)
    lens = turned.scene.lens
    c = _glare_centre(turned.render(T, [az, el], 1.0))
    assert c is not None and c[0] < lens.cx - 2.0 and abs(c[1] - lens.cy) < 1.0


def test_a_mounting_offset_moves_the_panel_not_the_shaft():
    now = [0.0]
    axes = [
        AxisParams(soft_min=0, soft_max=360, hard_min=-5, hard_max=365, initial_angle=120.0),
        AxisParams(soft_min=0, soft_max=90, hard_min=-5, hard_max=95, initial_angle=30.0),
    ]
    fw = DriveFirmware(axes, lambda: now[0])
    fw.mount_offsets = [1.5, -0.5]
    assert fw.true_angles() == pytest.approx([120.0, 30.0])
    assert fw.panel_angles() == pytest.approx([121.5, 29.5])
