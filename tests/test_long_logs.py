"""Long recordings (issue 30): what a run keeps grows with the intervals, not with the samples or
their square. Memory is bounded by counting allocations (tracemalloc: numpy reports its arrays to
it), never by timing; the speed lives in scripts/bench_memory.py."""
from __future__ import annotations

import tracemalloc

import numpy as np

from imucal.analysis.simulate import frame_matrix, mems_counts_sensor, random_directions
from imucal.constants import STANDARD_GRAVITY
from imucal.model.parameters import base_parameters
from imucal.model.sensor import build_model
from imucal.solve.fit import FitData, _sandwich, fit
from imucal.solve.initial import ellipsoid_guess


def _means(n: int, seed: int = 3) -> FitData:
    """``n`` interval means of a raw-count sensor, with a between-interval excess beyond their noise."""
    rng = np.random.default_rng(seed)
    sensor = mems_counts_sensor(np.random.default_rng(7))
    u = random_directions(n, rng)
    clean = np.asarray(sensor.s) + np.asarray(sensor.b) * (STANDARD_GRAVITY * u @ frame_matrix(np.asarray(sensor.angles)))
    sig = 0.2  # counts per mean
    raw = clean + rng.normal(0, sig, clean.shape) + rng.normal(0, 1.0, (n, 1))  # a bias per visit
    return FitData(raw=raw, cov=np.zeros((n, 0)), raw_var=np.full(raw.shape, sig**2), group=np.arange(n),
                   mode="means", t=np.arange(n) * 10.0)


def test_the_default_fit_of_many_means_holds_no_square_of_them() -> None:
    """weights="auto" on 4000 means: the rows' covariance is diagonal (no walk above
    stochastic.MAX_INTERVALS), kept as a vector: the fit allocates far less than one 4000 x 4000
    matrix (128 MB), which it once held (51 M samples, 38,000 intervals: 11.5 GB)."""
    n = 4000
    data = _means(n)
    g = ellipsoid_guess(data.raw, STANDARD_GRAVITY)
    params = base_parameters(g.s, g.b, g.angles, raw_unit="raw", gravity=STANDARD_GRAVITY)
    tracemalloc.start()
    try:
        res = fit(data, params, build_model(), STANDARD_GRAVITY, weights="auto")
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert res.success and res.excess > 0
    assert peak < n * n * 8 / 8, f"peak {peak / 2**20:.0f} MB"


def test_the_sandwich_of_a_diagonal_is_that_of_its_matrix() -> None:
    """The variances as a vector give the covariance the n x n diagonal matrix gives, bit for bit."""
    rng = np.random.default_rng(1)
    J, v = rng.normal(size=(50, 9)), rng.uniform(0.5, 2.0, 50)
    assert _sandwich(J, v, 1.7).tobytes() == _sandwich(J, np.diag(v), 1.7).tobytes()
