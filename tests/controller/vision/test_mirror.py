import numpy as np
from hypothesis import given, settings
from hypothesis import strategies as st

from controller.vision import level_rotation, mirror_sun_direction


def test_mirror_sign_flat_mirror():
    # camera to the south-up of a horizontal mirror; the sun must be to the north-up
    n = np.array([0.0, 0.0, 1.0])
    v = np.array([0.0, -0.6, 0.8])  # from the surface point TOWARD the camera
    s = mirror_sun_direction(n, v)
    np.testing.assert_allclose(s, [0.0, 0.6, 0.8], atol=1e-12)


def test_paper_r_convention_gives_the_opposite_direction():
    # the paper's r = point - camera = -v yields -s (the direction the light travels)
    n = np.array([0.0, 0.0, 1.0])
    v = np.array([0.3, -0.5, 0.81])
    v /= np.linalg.norm(v)
    s = mirror_sun_direction(n, v)
    r = -v
    s_paper = 2 * (r @ n) * n - r
    np.testing.assert_allclose(s_paper, -s, atol=1e-12)


unit = st.tuples(*[st.floats(-1, 1)] * 3).map(np.array).filter(lambda x: np.linalg.norm(x) > 0.2)


@settings(max_examples=200, deadline=None)
@given(unit, unit)
def test_mirror_inverts_the_half_vector(v, s):
    v = v / np.linalg.norm(v)
    s = s / np.linalg.norm(s)
    if v @ s < -0.95:
        return
    n = (v + s) / np.linalg.norm(v + s)  # normal that reflects the sun into the camera
    np.testing.assert_allclose(mirror_sun_direction(n, v), s, atol=1e-9)


@settings(max_examples=100, deadline=None)
@given(unit)
def test_level_rotation_maps_zenith_to_up(z):
    z = z / np.linalg.norm(z)
    R = level_rotation(z)
    np.testing.assert_allclose(R @ z, [0, 0, 1], atol=1e-9)
    np.testing.assert_allclose(R @ R.T, np.eye(3), atol=1e-12)
