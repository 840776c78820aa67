"""Shared synthetic data for the sky-type tests (generator: benchmarks/skytype.py)."""

from __future__ import annotations

import warnings

import pytest

from benchmarks.skytype import synthetic_dataset
from controller.sun.source import Site

SITE = Site(55.79, 12.52, 20.0)


@pytest.fixture(scope="session")
def dataset_1min():
    """40 days at 1-min with GHI and DNI, mixed regimes (seeded)."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return synthetic_dataset(
            SITE.latitude,
            SITE.longitude,
            SITE.altitude,
            60,
            2016,
            40,
            dict(clear=0.3, broken=0.3, overcast=0.3, mixed=0.1),
            seed=11,
        )


def one_regime(regime: str, step_s: int = 60, days: int = 3, seed: int = 3):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        return synthetic_dataset(
            SITE.latitude, SITE.longitude, SITE.altitude, step_s, 2016, days, {regime: 1.0}, seed=seed
        )
