import math

import numpy as np

from controller.vision.fisheye.sphere import centre_move, fit_cone, tangent_basis

FLOOR = math.radians(0.01)


def _rim(axis: np.ndarray, rho: float, phi: np.ndarray, moves: np.ndarray) -> np.ndarray:
    """Points of the cone about ``axis`` of half-angle ``rho`` at position angles ``phi``,
    each moved outwards by ``moves`` (rad)."""
    e1, e2 = tangent_basis(axis)
    r = rho + moves
    return np.cos(r)[:, None] * axis + np.sin(r)[:, None] * (
        np.cos(phi)[:, None] * e1 + np.sin(phi)[:, None] * e2
    )


def _fitted_move(phi: np.ndarray, moves: np.ndarray) -> float:
    """How far the cone fitted to the moved rim lies from the one fitted to the rim (rad)."""
    axis, rho = np.array([0.3, -0.2, 0.93]) / np.linalg.norm([0.3, -0.2, 0.93]), math.radians(6.0)
    before = fit_cone(_rim(axis, rho, phi, np.zeros_like(phi)), floor_rad=FLOOR)[0]
    after = fit_cone(_rim(axis, rho, phi, moves), floor_rad=FLOOR)[0]
    return math.acos(min(1.0, float(before @ after)))


def test_on_a_whole_rim_both_moves_are_the_first_harmonic_of_the_moves():
    phi = np.linspace(0.0, 2 * math.pi, 72, endpoint=False)
    moves = math.radians(0.2) + math.radians(0.1) * np.cos(phi - 0.4) + math.radians(0.05) * np.cos(2 * phi)
    fitted, harmonic = centre_move(moves, np.cos(phi), np.sin(phi))
    assert math.isclose(fitted, math.radians(0.1), rel_tol=1e-9)
    assert math.isclose(harmonic, math.radians(0.1), rel_tol=1e-9)
    assert math.isclose(fitted, _fitted_move(phi, moves), rel_tol=0.02)


def test_on_half_a_rim_the_fitted_move_is_the_fitted_cones():
    # the rim's horizon side lost: the harmonic and a fit differ
    phi = np.linspace(-math.pi / 2, math.pi / 2, 37)
    uniform = np.full_like(phi, math.radians(0.2))  # a wider glare: the radius takes it all
    fitted, harmonic = centre_move(uniform, np.cos(phi), np.sin(phi))
    assert fitted < 1e-12
    assert _fitted_move(phi, uniform) < math.radians(1e-4)
    assert harmonic > math.radians(0.24)
    bent = math.radians(0.2) * np.sin(phi) ** 2  # a sky model's error, largest at the gap
    fitted, harmonic = centre_move(bent, np.cos(phi), np.sin(phi))
    assert math.isclose(fitted, _fitted_move(phi, bent), rel_tol=0.05)
    assert fitted > 2.0 * harmonic


def test_too_few_or_collinear_points_have_no_fitted_move():
    assert centre_move(np.array([0.1, 0.2]), np.array([1.0, 0.0]), np.array([0.0, 1.0]))[0] == 0.0
    phi = np.array([0.3, 0.3, 0.3, 0.3])
    assert centre_move(np.array([0.1, 0.2, 0.3, 0.4]), np.cos(phi), np.sin(phi))[0] == 0.0
