import math

import numpy as np
import pytest

from controller.vision.fisheye.small import (
    _solve_spd_any,
    clip_unit,
    gradient,
    median,
    median_kept,
    median_rows,
    solve_spd,
)


@pytest.mark.parametrize("dtype", [np.float64, np.float32])
def test_median_is_numpys_value_for_value(dtype):
    rng = np.random.default_rng(5)
    for n in list(range(1, 12)) + [37, 100, 101]:
        for _ in range(20):
            x = rng.normal(size=n).astype(dtype)
            if n > 3:
                x[: n // 3] = x[0]  # ties
            rng.shuffle(x)
            assert median(x) == float(np.median(x))


def test_median_of_nothing_or_of_a_nan_is_nan():
    assert math.isnan(median(np.zeros(0)))
    for n in (1, 2, 5, 6):
        x = np.arange(n, dtype=float)
        x[n // 2] = np.nan
        assert math.isnan(median(x))


def test_median_leaves_its_argument_alone():
    x = np.array([3.0, 1.0, 2.0, 0.0])
    median(x)
    assert x.tolist() == [3.0, 1.0, 2.0, 0.0]


@pytest.mark.parametrize("n", [1, 2, 7, 36, 37])
def test_median_rows_is_numpys_value_for_value(n):
    x = np.random.default_rng(n).normal(size=(6, n))
    x[:, : n // 3] = x[:, :1]  # ties
    assert median_rows(x).tolist() == np.median(x, axis=1).tolist()


def test_median_kept_is_the_median_of_each_rows_kept_values():
    rng = np.random.default_rng(3)
    x = rng.normal(size=(40, 36))
    keep = rng.random((40, 36)) < rng.uniform(0.05, 1.0, (40, 1))
    keep[:, 0] = True
    x[~keep & (rng.random((40, 36)) < 0.5)] = np.nan  # what is not kept may be anything
    want = [float(np.median(row[k])) for row, k in zip(x, keep)]
    assert median_kept(x, keep).tolist() == want


@pytest.mark.parametrize("n", [1, 2, 4, 5])
def test_solve_spd_solves_normal_equations_as_numpy(n):
    rng = np.random.default_rng(n)
    for _ in range(50):
        J = rng.normal(size=(40, n)) * rng.uniform(0.01, 100.0, n)  # columns of any scale
        r = rng.normal(size=40)
        x = solve_spd((J.T @ J).tolist(), (J.T @ r).tolist())
        assert x is not None
        assert np.allclose(x, np.linalg.lstsq(J, r, rcond=None)[0], rtol=1e-8, atol=0)


@pytest.mark.parametrize("n", [4, 5])
def test_solve_spd_unrolled_is_the_loop_bit_for_bit(n):
    rng = np.random.default_rng(10 + n)
    for _ in range(200):
        J = rng.normal(size=(30, n)) * rng.uniform(0.01, 100.0, n)
        M, g = (J.T @ J).tolist(), rng.normal(size=n).tolist()
        assert solve_spd(M, g) == _solve_spd_any(M, g, 1e-10)


@pytest.mark.parametrize("n", [3, 4, 5])
@pytest.mark.parametrize("dep", [1, 2, -1])
def test_solve_spd_refuses_dependent_columns_and_leaves_its_arguments_alone(n, dep):
    rng = np.random.default_rng(0)
    J = rng.normal(size=(30, n))
    # all but dependent: a pivot of 1e-12 of its diagonal, where normal equations keep ~4 digits
    others = [j for j in range(n) if j != dep % n]
    J[:, dep] = J[:, others[0]] - 2.0 * J[:, others[1]] + 1e-6 * rng.normal(size=30)
    M, g = (J.T @ J).tolist(), [1.0 + j for j in range(n)]
    before = [row[:] for row in M]
    assert solve_spd(M, g) is None
    assert M == before and g == [1.0 + j for j in range(n)]
    assert solve_spd([[-1.0]], [1.0]) is None and solve_spd([[0.0]], [1.0]) is None


@pytest.mark.parametrize("n", [2, 3, 7, 40])
def test_gradient_is_numpys_value_for_value(n):
    rng = np.random.default_rng(n)
    for x in (
        np.arange(n) * 0.25,
        np.arange(0.0123, 0.0123 + n * 0.0017, 0.0017)[:n],
        np.sort(rng.uniform(0, 1, n)),
    ):
        for f in (rng.normal(size=n), rng.normal(size=n).astype(np.float32)):  # a profile of samples
            f[n // 2] = np.nan if n > 3 else f[n // 2]  # a NaN spreads to its neighbours alike
            g = gradient(f, x)
            assert g.dtype == np.gradient(f, x).dtype and np.array_equal(g, np.gradient(f, x), equal_nan=True)


def test_clip_unit_is_numpys_clip():
    x = np.array([-1.0000000000000002, -1.0, -0.3, 0.0, 1.0, 1.0000000000000002, 5.0, np.nan, -np.inf])
    assert np.array_equal(clip_unit(x), np.clip(x, -1.0, 1.0), equal_nan=True)
